"""worker_slices.py: a render's forked workers, frozen (lib.sh freeze_workers_at_birth), let run
a few milliseconds at a time until a poll of the dashboard shows what a test waits for.  Frozen
in between, the render cannot end while the test looks at it, on a machine of any speed: the
slices and sleeps only pace the loop, nothing waits on them."""
import os
import signal
import subprocess
import time


def signal_workers(coordinator, sig):
    """Send sig to every child of the coordinator (its forked workers)."""
    out = subprocess.run(["pgrep", "-P", str(coordinator)], capture_output=True, text=True).stdout
    for w in out.split():
        try:
            os.kill(int(w), sig)
        except ProcessLookupError:
            pass


def run_slices(coordinator, poll, enough, attempts=1200):
    """Thaw the workers for 20 ms, freeze them, wait for the dashboard's snapshot (refreshed
    every 200 ms) and poll, until enough(result) (which should also be true once the render
    has ended).  Returns every poll's result; the workers are left frozen."""
    results = []
    for _ in range(attempts):
        signal_workers(coordinator, signal.SIGCONT)
        time.sleep(0.02)
        signal_workers(coordinator, signal.SIGSTOP)
        time.sleep(0.25)
        results.append(poll())
        if enough(results[-1]):
            break
    return results
