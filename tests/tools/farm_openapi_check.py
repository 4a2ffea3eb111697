#!/usr/bin/env python3
"""tests/tools/farm_openapi_check.py: check a running standing farm against docs/farm-api.yaml
both ways (used by tests/e2e/farm_openapi.sh).

For every path and method in the spec it makes real requests: one that should succeed (with the
token kind the operation's security names, a body from the spec's example, a fresh job for
{id}), the same with the login cookie where the spec allows it, one without a token and one with
a token of the wrong kind.  Each status must be one the spec lists for the operation; a JSON
answer must match its schema (required properties present, types, enums, no property the spec
does not describe).  Then the other way: every method the spec does not list on its paths, and
a few paths it does not have, must answer 404.  Every answer must carry the security headers.

The routes probed the other way are the spec's paths with other methods, a few made-up paths,
and every path and job action named in the server's source (FARMAPI_C, coordinator/farm/farmapi.c),
so a route the server has and the spec lacks is found.

usage: farm_openapi_check.py SPEC HOST:PORT ADMIN_TOKEN WORKER_TOKEN SCENE DONE_JOB_ID [FARMAPI_C]
Prints one line per operation; exit 0 if all hold, else 1 with a FAIL line per problem."""
import http.client, json, re, sys, yaml

spec_path, addr, admin, worker, scene_path, done_job = sys.argv[1:7]
spec = yaml.safe_load(open(spec_path))
host, port = addr.rsplit(":", 1)
scene = open(scene_path).read()
problems = []
IDLE_POOL = "openapi-idle"  # no worker serves it: the checker's jobs stay where it put them
SECURITY_HEADERS = {"x-content-type-options": "nosniff", "x-frame-options": "DENY"}


def fail(msg):
    problems.append("FAIL: " + msg)
    print("FAIL: " + msg)


def request(method, path, headers=None, body=None):
    """(status, lower-cased headers, body bytes) of one request."""
    c = http.client.HTTPConnection(host, int(port), timeout=60)
    data = json.dumps(body).encode() if body is not None else None
    h = dict(headers or {})
    if data is not None:
        h["Content-Type"] = "application/json"
    c.request(method, path, body=data, headers=h)
    r = c.getresponse()
    out = (r.status, {k.lower(): v for k, v in r.getheaders()}, r.read())
    c.close()
    for k, v in SECURITY_HEADERS.items():
        if out[1].get(k) != v:
            fail("%s %s: header %s is %r, not %r" % (method, path, k, out[1].get(k), v))
    if "content-security-policy" not in out[1]:
        fail("%s %s: no Content-Security-Policy" % (method, path))
    return out


def auth(kind):
    """The headers of a caller of this kind (person, worker, cookie, none, cookie-bare)."""
    return {"person": {"Authorization": "Bearer " + admin},
            "worker": {"Authorization": "Bearer " + worker},
            "cookie": {"Cookie": "tf_farm_token=" + admin, "X-Terrafarm-Request": "1"},
            "cookie-bare": {"Cookie": "tf_farm_token=" + admin},
            "none": {}}[kind]


def resolve(s):
    while isinstance(s, dict) and "$ref" in s:
        node = spec
        for part in s["$ref"].lstrip("#/").split("/"):
            node = node[part]
        s = node
    return s


TYPES = {"object": dict, "array": list, "string": str, "boolean": bool}


def type_ok(t, v):
    if t in ("integer", "number"):
        return not isinstance(v, bool) and isinstance(v, int if t == "integer" else (int, float))
    return t is None or isinstance(v, TYPES[t])


def documented(schema):
    """Every property name an object schema (with its allOf parts) describes."""
    schema = resolve(schema)
    names = set(schema.get("properties", {}))
    for part in schema.get("allOf", []):
        names |= documented(part)
    return names


def check(schema, v, where, part=False):
    """v against schema; part: one allOf part (the whole checks for undescribed properties)."""
    schema = resolve(schema)
    for sub in schema.get("allOf", []):
        check(sub, v, where, part=True)
    if v is None:
        if not schema.get("nullable") and "allOf" not in schema:
            fail("%s: null, which the spec does not allow" % where)
        return
    if not type_ok(schema.get("type"), v):
        return fail("%s: %r is not of type %s" % (where, v, schema.get("type")))
    if "enum" in schema and v not in schema["enum"]:
        fail("%s: %r is not one of %s" % (where, v, schema["enum"]))
    if isinstance(v, dict):
        check_object(schema, v, where, part)
    if isinstance(v, list) and "items" in schema:
        for i, item in enumerate(v):
            check(schema["items"], item, "%s[%d]" % (where, i))


def check_object(schema, v, where, part):
    for name in schema.get("required", []):
        if name not in v:
            fail("%s: required property %r is missing" % (where, name))
    props = schema.get("properties", {})
    for k, item in v.items():
        if k in props:
            check(props[k], item, where + "." + k)
        elif isinstance(schema.get("additionalProperties"), dict):
            check(schema["additionalProperties"], item, where + "." + k)
    described = "properties" in schema or "allOf" in schema
    if described and not part and "additionalProperties" not in schema:
        extra = set(v) - documented(schema)
        if extra:
            fail("%s: properties the spec does not describe: %s" % (where, sorted(extra)))


def check_answer(op, where, status, headers, body):
    """The status is listed; a JSON body matches the listed response's schema."""
    responses = op["responses"]
    if str(status) not in responses:
        return fail("%s answered %d, which the spec does not list (%s)" % (where, status, sorted(responses)))
    resp = resolve(responses[str(status)])
    content = resp.get("content", {})
    ctype = headers.get("content-type", "").split(";")[0]
    if content and ctype not in content:
        return fail("%s %d: Content-Type %s, the spec says %s" % (where, status, ctype, sorted(content)))
    if ctype == "application/json" and body:
        check(content[ctype]["schema"], json.loads(body), "%s %d body" % (where, status))


# ---- preparing a request ----

def submit(pool=IDLE_POOL):
    s, _, b = request("POST", "/api/jobs", auth("person"),
                      {"scene": scene, "name": "openapi", "pool": pool, "options": ["--size", "32x24"]})
    if s != 201:
        sys.exit("FAIL: cannot submit a job to test with: %d %s" % (s, b[:200]))
    return json.loads(b)["id"]


def job_for(op_id):
    """A job in the state the operation needs to succeed."""
    if op_id == "getJobOutput":
        return int(done_job)
    j = submit()
    if op_id == "resumeJob":
        request("POST", "/api/jobs/%d/pause" % j, auth("person"), {})
    return j


def example_body(op):
    rb = resolve(op.get("requestBody"))
    if not rb:
        return None
    media = rb["content"]["application/json"]
    body = dict(media.get("example", {}))
    if op.get("operationId") == "submitJob":
        body.update(scene=scene, pool=IDLE_POOL)
    return body


def target(path, op, query=None):
    """The path with {id} filled for op, and the query the operation needs."""
    if "{id}" in path:
        path = path.replace("{id}", str(job_for(op.get("operationId"))))
    params = [p for p in op.get("parameters", []) if resolve(p).get("in") == "query" and resolve(p).get("required")]
    if params and query is None:
        query = "&".join("%s=%s" % (resolve(p)["name"], admin) for p in params)
    return path + ("?" + query if query else "")


def kinds(op):
    sec = op.get("security", spec.get("security", []))
    return [name for req in sec for name in req]


# ---- one operation ----

def check_operation(path, method, op):
    name = "%s %s" % (method.upper(), path)
    before = len(problems)
    ks = kinds(op)
    main = ks[0] if ks else "none"
    s, h, b = request(method.upper(), target(path, op), auth(main), example_body(op))
    check_answer(op, name + " as " + main, s, h, b)
    if s >= 400:
        fail("%s as %s did not succeed: %d %s" % (name, main, s, b[:200].decode(errors="replace")))
    if op.get("operationId") == "getJobOutput" and b[:4] != b"v/1\x01":
        fail("%s: the answer is not an OpenEXR file" % name)
    seen = [s]
    if "cookie" in ks:
        s, h, b = request(method.upper(), target(path, op), auth("cookie"), example_body(op))
        check_answer(op, name + " with the cookie", s, h, b)
        if s >= 400:
            fail("%s with the cookie did not succeed: %d %s" % (name, s, b[:200].decode(errors="replace")))
        seen.append(s)
    if ks:
        seen += check_refusals(path, method, op, name, ks)
    print("%s %-30s %s" % ("ok  " if len(problems) == before else "FAIL", name, " ".join(map(str, seen))))


def check_refusals(path, method, op, name, ks):
    """Without a token: 401; with a token of a kind the operation does not take: listed, refused."""
    out = []
    s, h, b = request(method.upper(), target(path, op), auth("none"), example_body(op))
    check_answer(op, name + " without a token", s, h, b)
    if s != 401:
        fail("%s without a token answered %d, not 401" % (name, s))
    out.append(s)
    for wrong in [k for k in ("person", "worker") if k not in ks]:
        s, h, b = request(method.upper(), target(path, op), auth(wrong), example_body(op))
        check_answer(op, name + " as " + wrong, s, h, b)
        if s < 400:
            fail("%s as %s (not in its security) answered %d" % (name, wrong, s))
        out.append(s)
    if "cookie" in ks and method != "get":
        s, h, b = request(method.upper(), target(path, op), auth("cookie-bare"), example_body(op))
        check_answer(op, name + " with the cookie but no X-Terrafarm-Request", s, h, b)
        if s != 403:
            fail("%s with the cookie alone answered %d, not 403" % (name, s))
        out.append(s)
    return out


# ---- the other way ----

METHODS = ["get", "post", "put", "delete", "patch"]
EXTRA_PATHS = ["/api", "/api/nope", "/api/farm/x", "/api/jobs/abc", "/api/jobs/0",
               "/api/jobs/{id}/explode", "/api/jobs/{id}/output/x", "/api/jobs/{id}/cancel/x",
               "/api/workers/x", "/api/workers/next/x", "/index.html", "/farm.html", "/dashboard.js"]


def source_paths(path):
    """The URL paths and job actions the server's source names."""
    text = open(path).read()
    urls = {u.rstrip("/") or "/" for u in re.findall(r'"(/[a-z0-9_./-]*)"', text) if ".." not in u}
    actions = re.findall(r'!strcmp\(a, "([a-z]+)"\)', text) + ["output"]
    return urls | {"/api/jobs/{id}/" + a for a in actions}


def check_unlisted():
    j = submit()
    n = 0
    paths = spec["paths"]
    extra = set(EXTRA_PATHS) | (source_paths(sys.argv[7]) if len(sys.argv) > 7 else set())
    routes = [(p, m) for p in paths for m in METHODS if m not in paths[p]]
    routes += [(p, m) for p in sorted(extra) for m in METHODS if p not in paths]
    for p, m in routes:
        url = p.replace("{id}", str(j))
        for kind in ("person", "worker"):
            s, _, b = request(m.upper(), url, auth(kind), {} if m != "get" else None)
            n += 1
            if s != 404:
                fail("%s %s (not in the spec) as %s answered %d, not 404: %s" % (m.upper(), url, kind, s, b[:120]))
    print("ok   %d requests to routes the spec does not list answered 404" % n)


def check_web():
    """The login page carries no data; the cookie is HttpOnly and SameSite=Strict."""
    s, h, b = request("GET", "/")
    if b"/login" not in b or b"/api/" in b or b"farm.js" in b:
        fail("GET / without a cookie is not the bare login page: %s" % b[:200])
    s, h, b = request("GET", "/login?token=" + admin)
    cookie = h.get("set-cookie", "")
    if "HttpOnly" not in cookie or "SameSite=Strict" not in cookie or h.get("location") != "/":
        fail("GET /login: cookie %r, Location %r" % (cookie, h.get("location")))
    s, h, b = request("GET", "/", auth("cookie-bare"))
    if b"farm.js" not in b:
        fail("GET / with the cookie is not the web view: %s" % b[:200])
    s, h, b = request("GET", "/login?token=" + worker)
    if s != 401 or "set-cookie" in h:
        fail("GET /login with the workers' token answered %d (%s)" % (s, h.get("set-cookie")))
    print("ok   login page without data, HttpOnly SameSite=Strict cookie, workers' token refused")


for path, item in spec["paths"].items():
    for method, op in item.items():
        if method in METHODS:
            check_operation(path, method, op)
check_unlisted()
check_web()
print("%d problems" % len(problems))
sys.exit(1 if problems else 0)
