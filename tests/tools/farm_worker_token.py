#!/usr/bin/env python3
"""tests/tools/farm_worker_token.py: print the standing farm's workers' bearer token from its
secret file, derived as common/farm_keys.c does (key = SHA-256 of the file without trailing
newlines, linda/auth.c; token = BLAKE2b-256 keyed by it of "terrafarm farm worker token v1"),
so tests can call the workers' routes without a worker.

usage: farm_worker_token.py SECRET_FILE"""
import hashlib, sys

data = open(sys.argv[1], "rb").read().rstrip(b"\r\n")
key = hashlib.sha256(data).digest()
print(hashlib.blake2b(b"terrafarm farm worker token v1", digest_size=32, key=key).hexdigest())
