#!/bin/sh
# farm_paint.sh: Raypaint on a standing farm (docs/paint.md, "On a standing farm").  Alice
# submits a still and pauses it, then opens a paint job of it (terrafarm job ID --paint, the
# web view's "paint" button): its page is up before any worker comes (the job's dashboard link
# is its page), a staying worker comes to it (one priority higher than the still) and paints
# it; the painted image equals a plain terrafarm render.  The page's Submit queues the view
# as alice's render job in the paint job's pool; closed (cancel), the paint job hands the
# worker to that job, whose output is the painted image pixel for pixel.  What it refuses: bob opening a paint of
# alice's job or the workers' token opening one (404, as for no job), a paint of a sequence (409), a
# paint job with a render-only option or an unknown kind (400).  The paint run's own token
# may only submit (it lists nothing, controls nothing) and dies with the run (401 after).
. "$(dirname "$0")/lib.sh"
e2e_init
. "$(dirname "$0")/lib_farm.sh"
farm_init
"$TF_BIN" farm --state "$T/state" --add-token bob --role submitter >"$T/bob" || fail "add-token bob"
start_farm
SIZE=160x96

# http METHOD PATH TOKEN [BODY] [BASE]: one request; its status printed, its body in $T/http.out
http() {
    python3 -c 'import http.client, sys, urllib.parse
method, url, token, body, out = sys.argv[1:6]
u = urllib.parse.urlsplit(url)
c = http.client.HTTPConnection(u.hostname, u.port, timeout=30)
h = {"Authorization": "Bearer " + token, "Content-Type": "application/json"}
c.request(method, u.path, body.encode() if body else None, h)
r = c.getresponse()
open(out, "wb").write(r.read())
print(r.status)' "$1" "${5:-http://$TERRAFARM_FARM}$2" "$3" "${4:-}" "$T/http.out"
}
expect() { # expect STATUS WHAT METHOD PATH TOKEN [BODY] [BASE]
    want=$1 what=$2; shift 2
    got=$(http "$@")
    [ "$got" = "$want" ] || fail "$what: HTTP $got, not $want: $(cat "$T/http.out")"
    say "$what: $got $(head -c 120 "$T/http.out")"
}
alice=$(tail -1 "$T/alice") bob=$(tail -1 "$T/bob")
worker=$(python3 -c 'import sys; sys.path.insert(0, sys.argv[2]); import farm_liar as f
print(f.worker_token(f.key_from_secret(sys.argv[1])))' "$T/secret" "$TF_ROOT/tests/tools")

say "alice's still, paused; a sequence"
still=$("$TF_BIN" submit "$SCENE" --size $SIZE --name still --pool studio) || fail "submit"
"$TF_BIN" pause "$still" >/dev/null || fail "pause"
seq=$("$TF_BIN" submit "$TF_ROOT/scenes/flyby.scene" --size 64x40 --frames 0-1 --name seq) ||
    fail "submit the sequence"
"$TF_BIN" pause "$seq" >/dev/null || fail "pause the sequence"

say "what a paint job refuses"
expect 404 "bob opens a paint of alice's job" POST "/api/jobs/$still/paint" "$bob" '{}'
expect 404 "the workers' token opens a paint" POST "/api/jobs/$still/paint" "$worker" '{}'
expect 409 "a paint of a sequence" POST "/api/jobs/$seq/paint" "$alice" '{}'
scene=$(python3 -c 'import json,sys; print(json.dumps(open(sys.argv[1]).read()))' "$SCENE")
expect 400 "a paint job with --tasks" POST /api/jobs "$alice" \
    "{\"scene\": $scene, \"kind\": \"paint\", \"options\": [\"--tasks\", \"rows:4\"]}"
expect 400 "a job of kind bake" POST /api/jobs "$alice" "{\"scene\": $scene, \"kind\": \"bake\"}"

say "alice opens a paint of her still: its page is up before any worker"
paint=$("$TF_BIN" job "$still" --paint) || fail "terrafarm job $still --paint"
wait_state "$paint" running 60
[ "$(field "$paint" kind)" = paint ] || fail "job $paint is a $(field "$paint" kind)"
[ "$(field "$paint" priority)" = 1 ] || fail "the paint job's priority is $(field "$paint" priority), not 1"
url=$(field "$paint" dashboard)
case "$url" in http://127.0.0.1:*/login\?token=*) ;; *) fail "the paint job's page is '$url'" ;; esac
page=${url%/login*} ptok=${url#*token=}
expect 200 "its page answers with no worker yet" GET /api/paint/status "$ptok" "" "$page"
grep -q '"workers": *0\|"workers":0' "$T/http.out" || fail "workers at the page: $(cat "$T/http.out")"

say "a staying worker paints it"
farm_worker w1 --pool studio
i=0
until [ "$(field "$paint" percent)" = 100.0 ]; do
    i=$((i + 1)); [ $i -lt 1500 ] || fail "not painted within 300 s: $(field "$paint" percent) %"
    sleep 0.2
done
dir=$T/state/jobs/$paint
i=0
until [ -s "$dir/painted.exr" ]; do
    i=$((i + 1)); [ $i -lt 300 ] || fail "the painted view was not written: $(cat "$dir/render.log")"
    sleep 0.2
done
render -q -j 2 --size $SIZE --http none -o "$T/ref.exr" || fail "reference: $(cat "$T/last.err")"
same_pixels "$T/ref.exr" "$dir/painted.exr" "painted on the farm"

say "the paint run's token may only submit"
run=$(cat "$dir/farm-token")
expect 200 "it lists" GET /api/jobs "$run"
grep -q '"jobs": *\[\]' "$T/http.out" || fail "the paint run's token saw jobs: $(cat "$T/http.out")"
expect 404 "it cancels alice's still" POST "/api/jobs/$still/cancel" "$run" '{}'

say "the page's Submit queues the view as alice's render"
expect 200 "Submit" POST /api/paint/submit "$ptok" "" "$page"
job=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["id"])' "$T/http.out")
[ "$(field "$job" owner)" = alice ] || fail "job $job belongs to $(field "$job" owner)"
[ "$(field "$job" kind)" = render ] || fail "job $job is a $(field "$job" kind)"
[ "$(field "$job" pool)" = studio ] || fail "job $job went to pool $(field "$job" pool), not the paint's"

say "closed, the paint job hands its worker to that render"
"$TF_BIN" cancel "$paint" >/dev/null || fail "cancel the paint job"
wait_state "$paint" cancelled 60
expect 401 "the closed run's token" POST /api/jobs "$run" "{\"scene\": $scene}"
wait_state "$job" done 300
"$TF_BIN" job "$job" --output "$T/submitted.exr" || fail "download job $job"
same_pixels "$dir/painted.exr" "$T/submitted.exr" "the submitted view, rendered by the farm"
[ "$(field "$still" state)" = paused ] || fail "the still is $(field "$still" state)"
echo "farm_paint: a paint job's page, its worker, its image, its Submit and its refusals all hold"
