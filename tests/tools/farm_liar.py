#!/usr/bin/env python3
"""farm_liar.py: the roles and the hostile inputs of a standing farm's HTTP API
(coordinator/farm/farmapi.c, farm_jobs.c, farm_workers.c), for tests/e2e/farm_roles.sh.

Given a running farm with no worker yet, the tokens of alice and bob (submitters) and root
(admin), and the farm's secret file (from which it derives the workers' token exactly as
common/farm_keys.c tf_farm_worker_token does), it checks, each with its HTTP status and a JSON
one-line error: no or a wrong token (401); bob can neither see (404, as for a job that does
not exist), control nor download alice's job; alice and root cannot act as workers (403), nor
list them unless admin; the workers' token cannot submit, list or see jobs; the admin sees and
controls every job; a height-map scene without its height map, a height map with another
scene, render options outside the allowed list and option values starting with '-' refused
(400) naming the rule; absurd bodies and paths (not an object, huge strings, a body over the
limit: 413, deep nesting, invalid UTF-8, odd ids) get a 4xx, the farm answering /api/farm
after each; a lying worker with the real workers' token (no name, a 10 KB name, unknown jobs,
terrains that are not hex, outcomes of jobs it never served, a negative or huge wait) gets a
4xx or a sensible answer, and is not counted on any job.

Usage: farm_liar.py HOST:PORT ALICE_TOKEN_FILE BOB_TOKEN_FILE ROOT_TOKEN_FILE SECRET_FILE
       DEFAULT_SCENE DEM_SCENE OUT_ID_FILE
Writes to OUT_ID_FILE the id of alice's job (queued, left for a real worker) and that of a job
whose height map is no raster (0 when the farm refused it at submission); prints what it
checks; on the first failure prints "FAIL: ..." and exits 1.
"""
import base64
import hashlib
import http.client
import json
import sys
import time


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def say(msg):
    print("-- " + msg, flush=True)


def key_from_secret(path):
    """tf_secret_load + tf_secret_from_bytes: SHA-256 of the file without trailing newlines."""
    data = open(path, "rb").read()
    data = data.rstrip(b"\r\n")
    return hashlib.sha256(data).digest()


def worker_token(key):
    """tf_farm_worker_token: keyed BLAKE2b-256 of the context string, in hex."""
    return hashlib.blake2b(b"terrafarm farm worker token v1", digest_size=32, key=key).hexdigest()


class Farm:
    def __init__(self, hostport):
        self.host, port = hostport.rsplit(":", 1)
        self.port = int(port)

    def call(self, method, path, token=None, body=None, timeout=120, headers=None):
        """(status, body bytes); body: dict (JSON), bytes, or an iterable of bytes with a
        Content-Length in headers."""
        c = http.client.HTTPConnection(self.host, self.port, timeout=timeout)
        h = dict(headers or {})
        if token is not None:
            h["Authorization"] = "Bearer " + token
        if isinstance(body, dict) or isinstance(body, list):
            body = json.dumps(body).encode()
        if isinstance(body, (bytes, bytearray)):
            h["Content-Type"] = "application/json"
        try:
            c.request(method, path, body=body, headers=h)
            r = c.getresponse()
            data = r.read()
            return r.status, data
        except (OSError, http.client.HTTPException) as e:
            fail(f"{method} {path[:80]}: no answer from the farm ({e})")
        finally:
            c.close()


def one_line_error(what, data):
    try:
        doc = json.loads(data)
    except ValueError:
        fail(f"{what}: the answer is not JSON: {data[:200]!r}")
    err = doc.get("error") if isinstance(doc, dict) else None
    if not isinstance(err, str) or not err or "\n" in err:
        fail(f"{what}: no one-line error in {data[:300]!r}")
    return err


def main():
    if len(sys.argv) != 9:
        fail(__doc__.strip().splitlines()[-4])
    farm = Farm(sys.argv[1])
    alice, bob, root = (open(p).read().strip() for p in sys.argv[2:5])
    wtok = worker_token(key_from_secret(sys.argv[5]))
    default_scene = open(sys.argv[6]).read()
    dem_scene = open(sys.argv[7]).read()
    out_id = sys.argv[8]

    def expect(what, method, path, token, body=None, status=200, contains=None, headers=None):
        st, data = farm.call(method, path, token, body, headers=headers)
        if st != status:
            fail(f"{what}: {method} {path[:80]} answered {st}, not {status}: {data[:300]!r}")
        if st >= 400:
            err = one_line_error(what, data)
            if contains and contains not in err:
                fail(f"{what}: the error does not say '{contains}': {err}")
            return err
        if st == 204 or not data:
            return None
        try:
            return json.loads(data)
        except ValueError:
            fail(f"{what}: the answer is not JSON: {data[:200]!r}")

    def alive(after):
        doc = expect(f"/api/farm after {after}", "GET", "/api/farm", root)
        if not isinstance(doc, dict) or "jobs" not in doc:
            fail(f"/api/farm after {after}: {doc}")

    def job(i, token=root):
        return expect(f"job {i}", "GET", f"/api/jobs/{i}", token)

    small = ["--size", "48x32"]

    # ---- who may call at all ----
    say("no token, a wrong token, a malformed header: 401")
    expect("no token", "GET", "/api/farm", None, status=401, contains="token")
    expect("no token on jobs", "GET", "/api/jobs", None, status=401)
    expect("no token submits", "POST", "/api/jobs", None, {"scene": default_scene}, status=401)
    expect("no token asks for work", "POST", "/api/workers/next", None, {"name": "x"},
           status=401)
    expect("a wrong token", "GET", "/api/jobs", "0" * 64, status=401, contains="token")
    expect("a wrong short token", "GET", "/api/jobs", "nope", status=401)
    expect("an empty token", "GET", "/api/jobs", "", status=401)
    expect("the worker token off by one", "POST", "/api/workers/next",
           wtok[:-1] + ("0" if wtok[-1] != "0" else "1"), {"name": "x"}, status=401)
    expect("an 8 KB token", "GET", "/api/jobs", "a" * 8192, status=401)
    expect("Basic, not Bearer", "GET", "/api/jobs", None, status=401,
           headers={"Authorization": "Basic " + base64.b64encode(b"alice:x").decode()})
    expect("a hash as the token", "GET", "/api/jobs",
           hashlib.sha256(alice.encode()).hexdigest(), status=401)
    alive("the 401s")

    # ---- submitters ----
    say("alice and bob submit; alice's job is hers alone")
    a = expect("alice submits", "POST", "/api/jobs", alice,
               {"scene": default_scene, "options": small, "name": "alice-job"}, status=201)
    a = a["id"]
    b = expect("bob submits", "POST", "/api/jobs", bob,
               {"scene": default_scene, "options": small, "name": "bob-job"}, status=201)["id"]
    ghost = b + 100000
    if job(a, alice)["owner"] != "alice":
        fail(f"job {a} is not alice's: {job(a, alice)}")

    say("bob cannot see, control or download alice's job: 404, as for a job that does not exist")
    mine = expect("bob shows alice's job", "GET", f"/api/jobs/{a}", bob, status=404)
    none = expect("bob shows no job", "GET", f"/api/jobs/{ghost}", bob, status=404)
    if mine.replace(str(a), "ID") != none.replace(str(ghost), "ID"):
        fail(f"bob tells alice's job from none: '{mine}' against '{none}'")
    for act, body in (("cancel", {}), ("pause", {}), ("resume", {}), ("priority", {"priority": 9}),
                      ("output", {})):
        e1 = expect(f"bob {act}s alice's job", "POST", f"/api/jobs/{a}/{act}", bob, body,
                    status=404)
        e2 = expect(f"bob {act}s no job", "POST", f"/api/jobs/{ghost}/{act}", bob, body,
                    status=404)
        if e1.replace(str(a), "ID") != e2.replace(str(ghost), "ID"):
            fail(f"bob's {act} tells alice's job from none: '{e1}' against '{e2}'")
    e1 = expect("bob downloads alice's output", "GET", f"/api/jobs/{a}/output", bob, status=404)
    e2 = expect("bob downloads no output", "GET", f"/api/jobs/{ghost}/output", bob, status=404)
    if e1.replace(str(a), "ID") != e2.replace(str(ghost), "ID"):
        fail(f"bob's download tells alice's job from none: '{e1}' against '{e2}'")
    listed = [j["id"] for j in expect("bob lists", "GET", "/api/jobs", bob)["jobs"]]
    if a in listed or b not in listed:
        fail(f"bob's list is {listed} (alice's {a}, his {b})")
    expect("bob depends on alice's job", "POST", "/api/jobs", bob,
           {"scene": default_scene, "after": a}, status=400, contains="after")
    if job(a)["state"] != "queued" or job(a)["priority"] != 0:
        fail(f"bob's attempts changed alice's job: {job(a)}")
    expect("alice's output before it is done", "GET", f"/api/jobs/{a}/output", alice, status=409,
           contains="not done")

    say("people are not workers: 403 on the workers' routes")
    for who, tok in (("alice", alice), ("root", root)):
        expect(f"{who} asks for a job", "POST", "/api/workers/next", tok,
               {"name": who, "wait_ms": 0}, status=403)
        expect(f"{who} heartbeats", "POST", "/api/workers/heartbeat", tok,
               {"name": who, "job": a}, status=403)
    expect("alice lists workers", "GET", "/api/workers", alice, status=403)
    expect("bob lists workers", "GET", "/api/workers", bob, status=403)

    say("the workers' token cannot submit, list or see jobs")
    expect("the worker submits", "POST", "/api/jobs", wtok, {"scene": default_scene}, status=403)
    expect("the worker lists jobs", "GET", "/api/jobs", wtok, status=403)
    expect("the worker shows a job", "GET", f"/api/jobs/{a}", wtok, status=404)
    expect("the worker cancels a job", "POST", f"/api/jobs/{a}/cancel", wtok, {}, status=404)
    expect("the worker downloads", "GET", f"/api/jobs/{a}/output", wtok, status=404)
    expect("the worker lists workers", "GET", "/api/workers", wtok, status=403)

    say("the admin sees and controls every job")
    listed = [j["id"] for j in expect("root lists", "GET", "/api/jobs", root)["jobs"]]
    if a not in listed or b not in listed:
        fail(f"root's list {listed} lacks {a} or {b}")
    if expect("root pauses alice's", "POST", f"/api/jobs/{a}/pause", root, {})["state"] != "paused":
        fail("root could not pause alice's job")
    expect("a paused job paused again", "POST", f"/api/jobs/{a}/pause", root, {}, status=409)
    if expect("root resumes", "POST", f"/api/jobs/{a}/resume", root, {})["state"] != "queued":
        fail("root could not resume alice's job")
    if expect("root sets priority", "POST", f"/api/jobs/{a}/priority", root,
              {"priority": 3})["priority"] != 3:
        fail("root could not set the priority of alice's job")
    expect("a priority out of range", "POST", f"/api/jobs/{a}/priority", root,
           {"priority": 100000}, status=400, contains="priority")
    expect("no such action", "POST", f"/api/jobs/{a}/explode", root, {}, status=404)
    expect("root lists workers", "GET", "/api/workers", root)
    if "history" not in job(a):
        fail("root sees no history")

    # ---- what a job may carry ----
    say("content rules: a height-map scene needs its height map, and only it may carry one")
    expect("a file scene without its height map", "POST", "/api/jobs", alice,
           {"scene": dem_scene, "options": small}, status=400, contains="carries none")
    hm = {"name": "dem.tif", "base64": base64.b64encode(b"\0\1 not a tif \0").decode()}
    expect("a height map with a non-file scene", "POST", "/api/jobs", alice,
           {"scene": default_scene, "heightmap": hm}, status=400, contains="generator is not file")
    for bad in ({"base64": "!!!"}, {"name": "x"}, "abc", None, 5, {"base64": ""}):
        expect(f"a malformed height map {bad!r}", "POST", "/api/jobs", alice,
               {"scene": dem_scene, "heightmap": bad}, status=400, contains="heightmap")
    # Bytes that are no raster: the farm does not decode a height map when it is submitted
    # (that would hold its lock for a large one), so it may queue the job; then the job must
    # end failed with a reason once a worker asks for it (farm_roles.sh checks that).
    st, data = farm.call("POST", "/api/jobs", alice,
                         {"scene": dem_scene, "heightmap": hm, "options": small,
                          "name": "garbage"})
    garbage = 0
    if st == 201:
        garbage = json.loads(data)["id"]
        say(f"bytes that are no raster were queued as job {garbage}: it must fail when served")
    elif st != 400:
        fail(f"a file scene with bytes that are no raster answered {st}: {data[:200]!r}")
    else:
        one_line_error("a file scene with bytes that are no raster", data)

    say("render options outside the list, and values that look like options, are refused")
    for opts in (["-o", "/tmp/x.exr"], ["--listen", "0.0.0.0:1"], ["--stats", "/tmp/s"],
                 ["--http", "0.0.0.0:80"], ["--secret-file", "/etc/shadow"], ["--output", "x"],
                 ["--size", "48x32", "--listen", "0.0.0.0:1"], ["-j", "64"], ["--size=48x32"],
                 ["--workers", "9"], [""], [5], [None], [["--size"]]):
        err = expect(f"options {opts}", "POST", "/api/jobs", alice,
                     {"scene": default_scene, "options": opts}, status=400,
                     contains="is not a render option a farm job may set")
        named = opts[2] if len(opts) > 2 else opts[0]
        if isinstance(named, str) and f"'{named}'" not in err:
            fail(f"options {opts}: the error does not name {named}: {err}")
    for flag in ("-o", "--listen", "--stats", "--http", "--secret-file", "--output", "-j",
                 "--workers", "--connect", "--resume", "--events"):
        for opts in ([flag], [flag, "x"], ["--verify-chunks", flag], [flag, "--verify-chunks"]):
            err = expect(f"options {opts}", "POST", "/api/jobs", alice,
                         {"scene": default_scene, "options": opts}, status=400,
                         contains=f"'{flag}' is not a render option a farm job may set")
    for opts in (["--size", "-48x32"], ["--size", "--listen"], ["--tasks", "-1"], ["--size"],
                 ["--size", ""], ["--size", "48x32 --listen"], ["--size", "x" * 100],
                 ["--size", 48], ["--watermark", "\u00e9t\u00e9"]):
        expect(f"option values {opts}", "POST", "/api/jobs", alice,
               {"scene": default_scene, "options": opts}, status=400, contains="plain value")
    say("option values the render would refuse when it starts are refused at submission")
    for opts, says in ((["--lease-timeout", "5ms"], "--lease-timeout '5ms': expected a duration"),
                       (["--size", "0x32"], "--size '0x32': expected WxH"),
                       (["--tasks", "rows:0"], "--tasks 'rows:0'"),
                       (["--pixel", "quarter"], "--pixel 'quarter': expected half or float"),
                       (["--verify", "2"], "--verify '2': expected a fraction from 0 to 1"),
                       (["--affinity", "maybe"], "--affinity 'maybe': expected on or off"),
                       (["--watermark", "0"], "--watermark '0': expected an integer"),
                       (["--wait-workers", "many"], "--wait-workers 'many': expected an integer"),
                       (["--frame", "2-5"], "--frame '2-5': expected one frame number"),
                       (["--frames", "5-2"], "the last frame is before the first"),
                       (["--frames", "0-1", "--frame", "1"], "give --frames or --frame once"),
                       (["--frames", "0-1"], "has no [animation] section")):
        expect(f"option values {opts}", "POST", "/api/jobs", alice,
               {"scene": default_scene, "options": opts, "name": "values"}, status=400,
               contains=says)
    expect("options not an array", "POST", "/api/jobs", alice,
           {"scene": default_scene, "options": "--size 48x32"}, status=400, contains="array")
    for field, value, rule in (("name", "x" * 10240, "name"), ("name", "../etc", "name"),
                               ("pool", "a b", "pool"), ("tags", "gpu;rm", "tags"),
                               ("priority", 5000, "priority"), ("priority", "high", "priority"),
                               ("after", "1", "after"), ("after", -1, "after"),
                               ("after", ghost, "after")):
        expect(f"{field} = {str(value)[:20]}", "POST", "/api/jobs", alice,
               {"scene": default_scene, field: value}, status=400, contains=rule)
    expect("no scene", "POST", "/api/jobs", alice, {"options": small}, status=400,
           contains="scene")
    expect("a scene that does not parse", "POST", "/api/jobs", alice,
           {"scene": "[terrain]\ngenerator = teapot\n"}, status=400)
    expect("a 2 MiB scene", "POST", "/api/jobs", alice, {"scene": "; " + "x" * (2 << 20)},
           status=400, contains="scene")
    alive("the content checks")

    # ---- absurd requests ----
    say("absurd bodies and paths: a 4xx each, and the farm keeps serving")
    absurd = [
        ("an array body", b"[1,2,3]", 400),
        ("a string body", b'"scene"', 400),
        ("null", b"null", 400),
        ("not JSON", b"{scene: yes", 400),
        ("a truncated object", b'{"scene": "[image]', 400),
        ("duplicate keys", b'{"scene": "a", "scene": "b"}', 400),
        ("invalid UTF-8", b'{"scene": "\xff\xfe\xc3(", "name": "x"}', 400),
        ("a NUL in a string", b'{"scene": "a\\u0000b"}', 400),
        ("deep nesting", b'{"a":' * 100000 + b"1" + b"}" * 100000, 400),
        ("deep arrays", b'{"scene": ' + b"[" * 200000 + b"]" * 200000 + b"}", 400),
        ("a huge number", b'{"scene": "x", "priority": 1' + b"0" * 400 + b"}", 400),
        ("a 16 MiB name", b'{"scene": "x", "name": "' + b"n" * (16 << 20) + b'"}', 400),
    ]
    for what, body, st in absurd:
        expect(what, "POST", "/api/jobs", alice, body, status=st)
        alive(what)
    # over the 96 MiB limit (100 MiB), sent in pieces: refused as too large
    size = 100 << 20
    chunk = b"x" * (1 << 20)
    st, data = farm.call("POST", "/api/jobs", alice, (chunk for _ in range(size >> 20)),
                         headers={"Content-Length": str(size),
                                  "Content-Type": "application/json"}, timeout=300)
    if st != 413:
        fail(f"a 100 MiB body answered {st}, not 413: {data[:200]!r}")
    one_line_error("a 100 MiB body", data)
    alive("a 100 MiB body")
    for method, path, st in (("GET", "/api/jobs/-1", 404), ("GET", "/api/jobs/0", 404),
                             ("GET", "/api/jobs/99999999999999999999", 404),
                             ("GET", "/api/jobs/-99999999999999999999", 404),
                             ("GET", "/api/jobs/1/../../etc", 404),
                             ("GET", "/api/jobs/1/../../../etc/passwd", 404),
                             ("GET", "/api/jobs/abc", 404), ("GET", "/api/jobs/", 404),
                             ("GET", "/api/jobs/1abc", 404), ("GET", "/api/jobs/%00", 404),
                             ("GET", "/api/../api/jobs", 404),
                             ("GET", "/api/nothing", 404),
                             ("DELETE", f"/api/jobs/{a}", 404), ("PUT", "/api/jobs", 404),
                             ("POST", "/api/farm", 404),
                             ("POST", f"/api/jobs/{a}/output", 404),
                             ("POST", "/api/jobs/99999999999999999999/cancel", 404),
                             ("GET", f"/api/jobs/{a}/output?frame=-99999999999", 409),
                             ("GET", "/api/workers/next", 404)):
        expect(f"{method} {path}", method, path, alice, {} if method != "GET" else None,
               status=st)
        alive(f"{method} {path}")

    # ---- a lying worker, with the real workers' token ----
    say("a lying worker: malformed next and heartbeat bodies")

    def workers():
        return {w["name"]: w for w in expect("workers", "GET", "/api/workers", root)["workers"]}

    for what, route, body in (
            ("no name", "next", {"pool": "liars", "wait_ms": 0}),
            ("an empty name", "next", {"name": "", "wait_ms": 0}),
            ("a number as name", "next", {"name": 123, "wait_ms": 0}),
            ("a 10 KB name", "next", {"name": "w" * 10240, "wait_ms": 0}),
            ("a name with a slash", "next", {"name": "../w", "wait_ms": 0}),
            ("a name with a newline", "next", {"name": "w\nx", "wait_ms": 0}),
            ("no name", "heartbeat", {"job": a}),
            ("a 10 KB name", "heartbeat", {"name": "w" * 10240, "job": a}),
            ("a list as name", "heartbeat", {"name": ["w"], "job": a})):
        expect(f"{route} with {what}", "POST", f"/api/workers/{route}", wtok, body, status=400,
               contains="name")
    expect("next with no body", "POST", "/api/workers/next", wtok, None, status=400)
    alive("malformed worker bodies")
    if any(n.startswith("w" * 50) or n == "" for n in workers()):
        fail(f"a refused worker name was recorded: {list(workers())}")

    say("a lying worker: unknown jobs, bad terrains, outcomes of jobs it never served")
    for job_id in (ghost, -1, 0, "x", 1e30, None):
        r = expect(f"heartbeat for job {job_id}", "POST", "/api/workers/heartbeat", wtok,
                   {"name": "liar", "job": job_id})
        if r != {"stay": False}:
            fail(f"a heartbeat for job {job_id} answered {r}, not stay false")
    r = expect("heartbeat for a job not running", "POST", "/api/workers/heartbeat", wtok,
               {"name": "liar", "job": a})
    if r != {"stay": False}:
        fail(f"a heartbeat for queued job {a} (no render) answered {r}")
    lies = {"name": "liar", "pool": "liars", "wait_ms": -5,
            "terrains": ["z" * 64, "0" * 63, "0" * 65, 5, None, ["x"], "g" * 64],
            "last": {"job": ghost, "outcome": "failed"}}
    t0 = time.monotonic()
    expect("next with a negative wait", "POST", "/api/workers/next", wtok, lies, status=204)
    if time.monotonic() - t0 > 9:
        fail("a negative wait_ms was not taken as no wait")
    liar = workers().get("liar")
    if not liar or liar["terrains"] != 0:
        fail(f"terrains that are no terrain keys (not 64 hex digits) were kept: {liar}")
    if liar["sessions"] != 0 or liar["job"] != 0:
        fail(f"an outcome for a job that does not exist counted: {liar}")
    for last in ({"job": a, "outcome": "failed"}, {"job": a, "outcome": "done"},
                 {"job": b, "outcome": "retreated"}, {"job": -3, "outcome": "failed"},
                 {"job": "x", "outcome": "failed"}, {"job": a, "outcome": 7},
                 {"job": a}, "failed", [a], {"job": 1e300, "outcome": "failed"}):
        for _ in range(4):
            expect(f"next with last {last}", "POST", "/api/workers/next", wtok,
                   {"name": "liar", "pool": "liars", "wait_ms": 0, "last": last}, status=204)
    for what, extra in (("terrains not a list", {"terrains": "abc"}),
                        ("100000 terrains", {"terrains": ["a" * 64] * 100000}),
                        ("a string wait", {"wait_ms": "forever"}),
                        ("a 10 KB pool", {"pool": "p" * 10240}),
                        ("a 10 KB tags", {"tags": "t," * 5120})):
        body = {"name": "liar2", "pool": "liars", "wait_ms": 0}
        body.update(extra)
        t0 = time.monotonic()
        st, data = farm.call("POST", "/api/workers/next", wtok, body, timeout=60)
        if st not in (204, 400, 413):  # a worker's body is at most 64 KiB
            fail(f"next with {what} answered {st}: {data[:200]!r}")
        if time.monotonic() - t0 > 30:
            fail(f"next with {what} took {time.monotonic() - t0:.0f} s (the longest wait is 10 s)")
        alive(f"next with {what}")
    t0 = time.monotonic()
    expect("next with a huge wait", "POST", "/api/workers/next", wtok,
           {"name": "liar3", "pool": "liars", "wait_ms": 10 ** 15}, status=204)
    if time.monotonic() - t0 > 40:
        fail(f"a huge wait_ms was not bounded: {time.monotonic() - t0:.0f} s")

    ws = workers()
    liar = ws.get("liar")
    if not liar:
        fail(f"the liar is not listed among the workers: {list(ws)}")
    if liar["job"] != 0:
        fail(f"the liar is counted on job {liar['job']}")
    if liar["sessions"] != 0:  # only the outcome of a job the farm sent it to counts
        fail(f"the liar's outcomes of jobs it was never sent to counted: {liar['sessions']} sessions")
    for i in (a, b):
        j = job(i)
        if j["workers"] != 0 or j["attempts"] != 0 or j["state"] != "queued":
            fail(f"the liar changed job {i}: {j}")
    alive("the lying worker")

    say("bob cancels his own job; alice's is left queued for a real worker")
    if expect("bob cancels his", "POST", f"/api/jobs/{b}/cancel", bob, {})["state"] != "cancelled":
        fail("bob could not cancel his own job")
    expect("a cancelled job resumed", "POST", f"/api/jobs/{b}/resume", bob, {}, status=409)
    if expect("root sets priority back", "POST", f"/api/jobs/{a}/priority", root,
              {"priority": 0})["priority"] != 0:
        fail("priority")
    with open(out_id, "w") as f:
        f.write(f"{a} {garbage}\n")
    print("farm_liar: roles, content rules, absurd requests and a lying worker all held")


if __name__ == "__main__":
    main()
