#!/usr/bin/env python3
"""tests/tools/lying_farm.py: a farm whose answers to the job commands lie.

Usage: lying_farm.py PORT_FILE

Serves what `terrafarm jobs`, `job ID`, `job ID --output F`, `pause ID` and `submit` ask of a
farm (docs/farm-api.yaml), each answer hostile in its own way: strings with escape sequences
and newlines where names, states and reasons go, fields missing or of the wrong type, an error
whose message would clear the terminal.  The commands must print what they can, with every
control byte harmless, and never crash.  Writes the port it listens on to PORT_FILE; runs until
killed."""
import json
import sys
from http.server import BaseHTTPRequestHandler, HTTPServer

ESC = "\x1b[2J\x1b]0;owned\x07"
JOBS = {"jobs": [
    {"id": 1, "name": "a" + ESC, "owner": "o\nterrafarm: forged", "state": "done" + ESC,
     "priority": 1, "pool": "p" + ESC, "workers": 2, "width": 8, "height": 8, "frames": 0},
    {"id": 2},                                    # every other field missing
    {"id": "x", "name": 5, "state": None, "pool": [], "width": "8"},  # the wrong types
]}
JOB = {1: {"name": "a" + ESC, "state": "failed", "priority": 1, "pool": "p", "workers": 0,
           "reason": "render died\nterrafarm: forged line" + ESC,
           "history": "queued\nrunning" + ESC + "\n\nfailed: x\x07y\n"},
       2: {"state": "queued"},                      # no name, reason or history
       3: {"reason": 7, "history": ["a"], "name": None}}


class Farm(BaseHTTPRequestHandler):
    def log_message(self, *args):
        pass

    def reply(self, code, body):
        data = body if isinstance(body, bytes) else json.dumps(body).encode()
        self.send_response(code)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)

    def do_GET(self):
        if self.path == "/api/jobs":
            return self.reply(200, JOBS)
        if self.path.startswith("/api/jobs/") and "/output" in self.path:
            return self.reply(404, {"error": "no output\n" + ESC})
        try:
            return self.reply(200, JOB[int(self.path.rsplit("/", 1)[1])])
        except (KeyError, ValueError):
            return self.reply(404, b"not json at all\x1b[2J\nsecond line")

    def do_POST(self):
        length = int(self.headers.get("Content-Length", "0"))
        self.rfile.read(length)
        if self.path.endswith("/pause"):
            return self.reply(200, {"state": None, "priority": "high"})
        return self.reply(400, {"error": "refused" + ESC + "\nterrafarm: forged"})


server = HTTPServer(("127.0.0.1", 0), Farm)
with open(sys.argv[1] + ".tmp", "w") as f:
    f.write(str(server.server_address[1]))
import os  # noqa: E402 (the rename makes the port file appear whole)
os.rename(sys.argv[1] + ".tmp", sys.argv[1])
server.serve_forever()
