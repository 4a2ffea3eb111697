#!/bin/bash
# povray_compare.sh: terrafarm against POV-Ray 3.7 on the same height field, side by side, in one
# run (docs/contract.md section 6: "the same height field, camera, size and antialiasing in <= 1/3 of
# POV-Ray's time per core").  Method and results: bench/README-povray.md.
#
# For each height-field size 2^K+1 it
#   1. exports the scene's terrain with `terrafarm heightfield -k K` (16-bit PNG) and reads the
#      exact POV-Ray transform that command prints;
#   2. writes a derived scene (same scene, size_exp = K) for terrafarm and a .pov for POV-Ray
#      with the same camera, image size, sun (parallel light with shadows) and sky colour; POV-Ray
#      gets a plain pigment and `smooth` normals (terrafarm interpolates vertex normals too);
#   3. times both on ONE core, interleaved, RUNS times each, in these antialiasing modes:
#        aa     terrafarm adaptive (the scene's threshold and max_depth) vs POV-Ray +AM1 +A0.3 +R3
#        aa-eq  the same terrafarm run vs POV-Ray +AM1 +R3 with the threshold --pov-eq (default
#               0.005), which makes POV-Ray subdivide about as many pixels as terrafarm does
#               (at +A0.3 it refines almost none: compare the rays per pixel columns)
#        noaa   terrafarm max_depth 0 (one ray per pixel corner) vs POV-Ray -A
#      terrafarm runs `terrafarm render -j 1` (the product: coordinator + one forked worker,
#      terrain synthesis, EXR and PNG output); POV-Ray runs `povray +WT1` (one render thread,
#      parsing the PNG included).
#   4. prints the medians of whole-process CPU time (user + sys, children included: robust on
#      a shared machine) and of wall time; the CPU time of the render proper: for POV-Ray its
#      own trace CPU-seconds, for terrafarm the thread CPU time of one tf_render_rect over the
#      whole image (build/bench/povray_tf_render: a worker's task, without terrain synthesis
#      and what is built once with it -- the sun's strips, as POV-Ray builds its bounding at
#      parse time --, tuple traffic or file output); the camera rays per pixel of each; and the ratios
#      terrafarm / POV-Ray (targets <= 0.25, issue 23, and <= 1/3, docs/contract.md).
#
# Coordinates: terrafarm is right-handed with z up; POV-Ray is left-handed with y up.  The map
# (x, y, z) -> (x, z, y) swaps two axes, which is exactly a change of handedness, so the view is
# the same picture, not a mirror image.  The height field's own mirror in z (row 0 = near edge)
# is in the transform printed by `terrafarm heightfield`.  terrafarm's sea (an infinite plane at
# materials.sea_level) is a plain POV-Ray plane.
#
# usage: bench/povray_compare.sh [--scene FILE] [--sizes 9,11] [--image WxH] [--runs N]
#                                [--modes aa,aa-eq,noaa] [--pov-eq A] [--plain] [--keep DIR]
#   --plain   terrafarm without bump noise, snow-line noise and mist (tracing + plain shading
#             only, the closest to POV-Ray's plain pigment); default: the scene as written.
#   --keep    copy the .pov files, derived scenes and both pictures of each case to DIR.
#   --smoke   --sizes 6 --image 16x9 --runs 1 --modes noaa (a later option still wins): for
#             tests/e2e/bench_smoke.sh.
# env: TF (default bin/terrafarm) and TF_BUILD (default build/): the binaries to time; the
# defaults are built here first.
# Exit status: 0 done, 77 povray not installed (skip), 1 error.  Run from anywhere.
set -u

ROOT=$(cd "$(dirname "$0")/.." && pwd)
SCENE="$ROOT/scenes/default.scene"
SIZES="9,11"
IMAGE=""
RUNS=3
MODES="aa,aa-eq,noaa"
POV_EQ_THRESH=0.005
PLAIN=0
KEEP=""

die() { echo "povray_compare: $*" >&2; exit 1; }

while [ $# -gt 0 ]; do
    case "$1" in
    --scene) SCENE=$2; shift 2 ;;
    --sizes) SIZES=$2; shift 2 ;;
    --image) IMAGE=$2; shift 2 ;;
    --runs) RUNS=$2; shift 2 ;;
    --modes) MODES=$2; shift 2 ;;
    --pov-eq) POV_EQ_THRESH=$2; shift 2 ;;
    --plain) PLAIN=1; shift ;;
    --keep) KEEP=$2; shift 2 ;;
    --smoke) SIZES=6; IMAGE=16x9; RUNS=1; MODES=noaa; shift ;;
    -h|--help) sed -n '2,/^set -u/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown argument '$1' (try --help)" ;;
    esac
done

command -v povray >/dev/null 2>&1 || { echo "povray_compare: povray not installed (apt-get install povray): skipped"; exit 77; }
[ -r "$SCENE" ] || die "cannot read scene '$SCENE'"
case "$RUNS" in ''|*[!0-9]*|0) die "--runs wants a positive integer, not '$RUNS'" ;; esac
if [ -n "$IMAGE" ]; then
    case "$IMAGE" in [1-9]*x[1-9]*) ;; *) die "--image wants WxH, not '$IMAGE'" ;; esac
fi
SCENE=$(cd "$(dirname "$SCENE")" && pwd)/$(basename "$SCENE")

# Build what we run (quietly; a failure shows make's own message), unless given (tests/run.sh
# gives TF_BIN and TF_BUILD: under `make asan` those are build-asan's, which plain make knows
# nothing of).
TF=${TF:-${TF_BIN:-}}
if [ -z "$TF" ] || [ -z "${TF_BUILD:-}" ]; then
    make -s -C "$ROOT" bin/terrafarm build/bench/povray_tf_render >/dev/null || die "build failed"
fi
TF_RENDER="${TF_BUILD:-$ROOT/build}/bench/povray_tf_render"
TF="${TF:-$ROOT/bin/terrafarm}"

WORK=$(mktemp -d "${TMPDIR:-/tmp}/povcmp.XXXXXX") || die "mktemp failed"
trap 'rm -rf "$WORK"' EXIT

# ---------------------------------------------------------------- reading the scene

# ini_get SECTION KEY: the value with comments and surrounding blanks removed ("" if absent).
ini_get() {
    awk -v sec="$1" -v key="$2" '
        { sub(/[;#].*/, "") }
        /^[ \t]*\[/ { s = $0; gsub(/[][ \t]/, "", s); cur = s; next }
        cur == sec {
            i = index($0, "=")
            if (i == 0) next
            k = substr($0, 1, i - 1); v = substr($0, i + 1)
            gsub(/^[ \t]+|[ \t]+$/, "", k); gsub(/^[ \t]+|[ \t]+$/, "", v)
            if (k == key) val = v
        }
        END { print val }' "$SCENE"
}

# Three numbers "a, b, c" or "a b c" -> "a b c"; dies unless there are exactly three.
vec3() {
    local v
    v=$(echo "$1" | tr ',' ' ' | xargs)
    [ "$(echo "$v" | wc -w)" -eq 3 ] || die "expected three numbers for $2, got '$1'"
    echo "$v"
}

# Terrafarm (x, y, z) with z up -> POV-Ray <x, z, y> with y up.
pov_point() { set -- $1; echo "<$1, $3, $2>"; }

CAM_TYPE=$(ini_get camera type)
[ -z "$CAM_TYPE" ] || [ "$CAM_TYPE" = pinhole ] || die "only pinhole cameras compare to POV-Ray's perspective camera (scene has '$CAM_TYPE')"
CAM_UP=$(ini_get camera up)
if [ -n "$CAM_UP" ]; then
    set -- $(vec3 "$CAM_UP" "camera.up")
    awk -v x="$1" -v y="$2" 'BEGIN { exit !(x == 0 && y == 0) }' || die "camera.up must be +z for this comparison"
fi
CAM_POS=$(vec3 "$(ini_get camera position)" camera.position)
CAM_LOOK=$(vec3 "$(ini_get camera look_at)" camera.look_at)
FOV=$(ini_get camera fov); FOV=${FOV:-60}
SUN_AZ=$(ini_get sun azimuth); SUN_AZ=${SUN_AZ:-0}
SUN_EL=$(ini_get sun elevation); SUN_EL=${SUN_EL:-45}
SUN_COL=$(vec3 "$(ini_get sun color)" sun.color)
SUN_I=$(ini_get sun intensity); SUN_I=${SUN_I:-1}
SKY_HOR=$(vec3 "$(ini_get sky horizon)" sky.horizon)
SKY_ZEN=$(vec3 "$(ini_get sky zenith)" sky.zenith)
SKY_I=$(ini_get sky intensity); SKY_I=${SKY_I:-0.3}
SEA=$(ini_get materials sea_level); SEA=${SEA:-0}
if [ -z "$IMAGE" ]; then
    W=$(ini_get image width); H=$(ini_get image height)
    IMAGE="${W}x${H}"
fi
W=${IMAGE%x*}; H=${IMAGE#*x}

# ---------------------------------------------------------------- the two inputs

# derived_scene K OUT [DEPTH]: the scene with size_exp = K, antialias max_depth = DEPTH if given
# (and, with --plain, no textures or mist).
derived_scene() {
    awk -v k="$1" -v depth="${3:-}" -v plain="$PLAIN" '
        /^[ \t]*\[/ { t = $0; sub(/[;#].*/, "", t); gsub(/[][ \t]/, "", t); cur = t }
        { line = $0; key = line; sub(/=.*/, "", key); gsub(/[ \t]/, "", key) }
        cur == "terrain" && key == "size_exp" { print "size_exp = " k; seen = 1; next }
        depth != "" && cur == "antialias" && key == "max_depth" { next }
        depth != "" && /^[ \t]*\[antialias\]/ { print; print "max_depth = " depth; has_aa = 1; next }
        plain && cur == "materials" && (key == "bump" || key == "snow_jitter") { print key " = 0"; next }
        plain && cur == "mist" && key == "enabled" { print "enabled = no"; next }
        { print }
        END { if (depth != "" && !has_aa) { print "[antialias]"; print "max_depth = " depth }
              if (!seen) exit 3 }' "$SCENE" >"$2" || die "scene has no [terrain] size_exp line to override"
}

# pov_file K PNG_NAME OUT: the POV-Ray scene, from the transform `terrafarm heightfield` printed.
pov_file() {
    local k=$1 png=$2 out=$3 scale translate
    scale=$(sed -n 's/^ *scale \(<.*>\)$/\1/p' "$WORK/hf_$k.txt")
    translate=$(sed -n 's/^ *translate \(<.*>\) }$/\1/p' "$WORK/hf_$k.txt")
    [ -n "$scale" ] && [ -n "$translate" ] || die "could not read the POV-Ray transform from terrafarm heightfield"
    # Sun direction, terrafarm: (sin az cos el, cos az cos el, sin el); in POV-Ray order.
    local sun
    sun=$(awk -v a="$SUN_AZ" -v e="$SUN_EL" 'BEGIN { d = atan2(0, -1) / 180
        printf "<%.9f, %.9f, %.9f>", sin(a*d)*cos(e*d), sin(e*d), cos(a*d)*cos(e*d) }')
    set -- $SUN_COL; local sun_rgb="<$1, $2, $3> * $SUN_I"
    set -- $SKY_HOR; local hor="<$1, $2, $3>"
    set -- $SKY_ZEN; local zen="<$1, $2, $3>"
    cat >"$out" <<EOF
// Generated by bench/povray_compare.sh from $(basename "$SCENE") with size_exp $k.
// terrafarm (x, y, z up) -> POV-Ray <x, z, y> (y up).
#version 3.7;
global_settings { assumed_gamma 1.0 max_trace_level 2 }
camera {
  perspective
  location $(pov_point "$CAM_POS")
  look_at  $(pov_point "$CAM_LOOK")
  right    x * $W / $H
  up       y
  angle    $FOV
}
// The sun: a parallel light from the scene's azimuth and elevation, with shadows.
light_source { $sun * 1e7 color rgb $sun_rgb parallel point_at <0, 0, 0> }
// The sky: terrafarm's zenith/horizon gradient (no sun glow).
sky_sphere { pigment { function { max(0, y) } color_map { [0 color rgb $hor] [1 color rgb $zen] } } }
// terrafarm's water: an infinite plane at sea_level (plain, no ripples or reflection).
plane { y, $SEA pigment { color rgb <0.02, 0.05, 0.08> } finish { ambient rgb $zen * $SKY_I diffuse 0.3 } }
height_field {
  png "$png" smooth
  scale $scale
  translate $translate
  pigment { color rgb <0.20, 0.26, 0.12> }
  finish { ambient rgb ($zen + $hor) * 0.5 * $SKY_I diffuse 1 }
}
EOF
}

# ---------------------------------------------------------------- timing

# run_timed LOG CMD...: run CMD with stdout+stderr to LOG; prints "WALL CPU" in seconds.
run_timed() {
    local log=$1; shift
    /usr/bin/time -f "%e %U %S" -o "$WORK/time.txt" "$@" >"$log" 2>&1 || { cat "$log" >&2; die "'$*' failed"; }
    awk '{ printf "%.3f %.3f\n", $1, $2 + $3 }' "$WORK/time.txt"
}

median() { sort -g | awk '{ v[NR] = $1 } END { if (NR % 2) print v[(NR + 1) / 2]; else printf "%.3f\n", (v[NR/2] + v[NR/2 + 1]) / 2 }'; }

# POV-Ray's own trace CPU time: "Trace Time: ... using 1 thread(s) with 1.234 CPU-seconds total".
pov_trace_s() { sed -n 's/.*using [0-9]* thread(s) with \([0-9.]*\) CPU-seconds.*/\1/p' "$1" | tail -1; }
# POV-Ray camera rays per pixel: its statistics line "Rays: N" counts every ray but shadow
# rays; with no reflection or refraction in the scene those are the camera rays (the
# "Pixels:" count plus the antialiasing "Samples:").
pov_rays_pp() { awk -v px="$(( W * H ))" '/^Rays:/ { printf "%.2f", $2 / px }' "$1"; }
# terrafarm's statistics JSON: camera rays traced per pixel (a sample on the edge between two
# pixels of a task is traced once: bench/README-povray.md).
tf_rays_pp() {
    awk -v px="$(( W * H ))" '/"primary_rays"/ { gsub(/[^0-9]/, "", $2); printf "%.2f", $2 / px }' "$1"
}

# ---------------------------------------------------------------- the runs

printf "scene %s, image %s, %d runs each (median), one core each; %s\n" \
    "$(basename "$SCENE")" "$IMAGE" "$RUNS" "$( [ $PLAIN = 1 ] && echo 'terrafarm --plain (no bump, snow noise, mist)' || echo 'terrafarm shading as in the scene')"
printf "%-6s %-5s | %9s %9s %8s %6s | %9s %9s %8s %6s | %7s %7s\n" \
    "hf" "aa" "tf cpu s" "tf wall" "tf rend" "rays" "pov cpu" "pov wall" "pov trc" "rays" "cpu x" "trace x"

IFS=',' read -r -a SIZE_LIST <<<"$SIZES"
IFS=',' read -r -a MODE_LIST <<<"$MODES"
for k in "${SIZE_LIST[@]}"; do
    case "$k" in [1-9]|1[0-3]) ;; *) die "--sizes wants exponents 1..13, not '$k'" ;; esac
    n=$(( (1 << k) + 1 ))
    "$TF" heightfield "$SCENE" -k "$k" -t 1 -o "$WORK/hf_$k.png" >"$WORK/hf_$k.txt" 2>&1 ||
        { cat "$WORK/hf_$k.txt" >&2; die "terrafarm heightfield failed"; }
    pov_file "$k" "hf_$k.png" "$WORK/hf_$k.pov"
    for mode in "${MODE_LIST[@]}"; do
        case "$mode" in
        aa) depth=""; pov_args=(+A0.3 +AM1 +R3) ;;
        aa-eq) depth=""; pov_args=(+A"$POV_EQ_THRESH" +AM1 +R3) ;;
        noaa) depth=0; pov_args=(-A) ;;
        *) die "--modes wants aa, aa-eq and/or noaa, not '$mode'" ;;
        esac
        derived_scene "$k" "$WORK/tf_${k}_$mode.scene" "$depth"
        : >"$WORK/tf_cpu"; : >"$WORK/tf_wall"; : >"$WORK/pov_cpu"; : >"$WORK/pov_wall"
        : >"$WORK/tf_rend"; : >"$WORK/pov_trc"
        for ((r = 0; r < RUNS; r++)); do
            # Interleaved, so a burst of load from elsewhere hits both sides alike.
            set -- $(run_timed "$WORK/tf.log" "$TF" render "$WORK/tf_${k}_$mode.scene" -j 1 -q \
                --size "$IMAGE" -o "$WORK/tf_${k}_$mode.exr" --stats "$WORK/tf.json")
            echo "$1" >>"$WORK/tf_wall"; echo "$2" >>"$WORK/tf_cpu"
            "$TF_RENDER" "$WORK/tf_${k}_$mode.scene" "$WORK/tf_rect.png" "$IMAGE" >"$WORK/tf_rect.log" 2>&1 ||
                { cat "$WORK/tf_rect.log" >&2; die "povray_tf_render failed"; }
            sed -n 's/^render_cpu_s=\([0-9.]*\) .*/\1/p' "$WORK/tf_rect.log" >>"$WORK/tf_rend"
            set -- $(cd "$WORK" && run_timed "$WORK/pov.log" povray +I"hf_$k.pov" +O"pov_${k}_$mode.png" \
                +FN +W"$W" +H"$H" +WT1 -D -P +V "${pov_args[@]}")
            echo "$1" >>"$WORK/pov_wall"; echo "$2" >>"$WORK/pov_cpu"
            pov_trace_s "$WORK/pov.log" >>"$WORK/pov_trc"
        done
        tc=$(median <"$WORK/tf_cpu"); tw=$(median <"$WORK/tf_wall"); tr=$(median <"$WORK/tf_rend")
        pc=$(median <"$WORK/pov_cpu"); pw=$(median <"$WORK/pov_wall"); pt=$(median <"$WORK/pov_trc")
        ratio=$(awk -v a="$tc" -v b="$pc" 'BEGIN { if (b > 0) printf "%.3f", a / b; else print "?" }')
        tratio=$(awk -v a="$tr" -v b="$pt" 'BEGIN { if (b > 0) printf "%.3f", a / b; else print "?" }')
        printf "%-6s %-5s | %9s %9s %8.4f %6s | %9s %9s %8s %6s | %7s %7s\n" \
            "$n" "$mode" "$tc" "$tw" "$tr" "$(tf_rays_pp "$WORK/tf.json")" \
            "$pc" "$pw" "${pt:-?}" "$(pov_rays_pp "$WORK/pov.log")" "$ratio" "$tratio"
        if [ -n "$KEEP" ]; then
            mkdir -p "$KEEP" || die "cannot create $KEEP"
            cp "$WORK/tf_${k}_$mode.png" "$KEEP/terrafarm_${n}_$mode.png"
            cp "$WORK/hf_$k.png" "$WORK/tf_${k}_$mode.scene" "$KEEP/"
            cp "$WORK/pov_${k}_$mode.png" "$KEEP/povray_${n}_$mode.png"
            cp "$WORK/hf_$k.pov" "$WORK/pov.log" "$KEEP/"
            mv "$KEEP/pov.log" "$KEEP/povray_${n}_$mode.log"
        fi
    done
done
echo "rays = camera rays traced per pixel; tf rend = CPU of terrafarm's render proper (one"
echo "tf_render_rect over the image); pov trc = POV-Ray's trace CPU-seconds; cpu x = whole-process"
echo "CPU ratio; trace x = tf rend / pov trc (targets: <= 0.25, issue 23; <= 1/3, docs/contract.md)"
