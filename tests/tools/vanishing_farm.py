#!/usr/bin/env python3
"""tests/tools/vanishing_farm.py: a farm whose job's render is never there.

Usage: vanishing_farm.py PORT_FILE OUTCOME_FILE

Serves the two calls of the farm's worker API that `terrafarm worker --connect http://...`
makes (coordinator/farm/farmapi.c): POST /api/workers/next and /api/workers/heartbeat.  The
first /next assigns job 7, a render, at a port where a socket is bound but not listening, so
the worker's connection is refused: the job's render has gone, as a render does when it dies
between the farm's assignment and the worker's connect.  The worker's next /next reports how
that session ended ("last": {"job": 7, "outcome": ...}); the outcome is written to
OUTCOME_FILE and every later /next gets no job.  Writes the port it listens on to PORT_FILE.
Runs until killed."""
import json
import os
import socket
import sys
from http.server import BaseHTTPRequestHandler, HTTPServer

port_file, outcome_file = sys.argv[1], sys.argv[2]

# bound, never listening: a connect to it is refused (RST), every time, at once
gone = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
gone.bind(("127.0.0.1", 0))
GONE_PORT = gone.getsockname()[1]
state = {"assigned": False, "reported": False}


class Farm(BaseHTTPRequestHandler):
    def log_message(self, *args):
        pass

    def reply(self, body):
        data = json.dumps(body).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)

    def do_POST(self):
        n = int(self.headers.get("Content-Length", "0"))
        req = json.loads(self.rfile.read(n) or b"{}")
        if self.path == "/api/workers/heartbeat":
            self.reply({"stay": False})
            return
        if self.path != "/api/workers/next":
            self.send_error(404)
            return
        last = req.get("last")
        if state["assigned"] and not state["reported"] and isinstance(last, dict):
            with open(outcome_file, "w") as f:
                f.write("%s %s\n" % (last.get("job"), last.get("outcome")))
            state["reported"] = True
        if not state["assigned"]:
            state["assigned"] = True
            self.reply({"job": 7, "nonce": "00" * 16, "terrain": "ab" * 32, "name": "vanishing",
                        "kind": "render", "port": GONE_PORT})
            return
        self.reply({"job": 0})


server = HTTPServer(("127.0.0.1", 0), Farm)
with open(port_file + ".tmp", "w") as f:
    f.write("%d\n" % server.server_address[1])
os.rename(port_file + ".tmp", port_file)
server.serve_forever()
