#!/bin/sh
# tests/e2e/deploy_container.sh: deploy/container/Containerfile (no container engine needed:
# the file is checked, not built).  Required: a debian:12 build stage that installs the -dev
# package of every library the Makefile links (cross-checked against the Makefile's pkg-config
# list), builds bin/terrafarm from a clean tree; a debian:12 run stage with the matching
# run-time libraries, the binary, a non-root user and terrafarm as the entry point; and the
# .dockerignore beside it keeping host build outputs out of the context.
set -u
ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
C=$ROOT/deploy/container/Containerfile
fail() { echo "FAIL: $*"; exit 1; }
[ -r "$C" ] || fail "$C is missing"

need() {
    grep -Eq "$1" "$C" || fail "Containerfile lacks: $1"
}
[ "$(grep -c '^FROM debian:12' "$C")" -eq 2 ] || fail "expected two FROM debian:12 stages"
need '^FROM debian:12 AS build$'
need '^COPY \. /src$'
need '^RUN make clean && make .*bin/terrafarm'
need '^COPY --from=build /src/bin/terrafarm /usr/local/bin/terrafarm$'
need '^USER [1-9][0-9]*$'
need '^ENTRYPOINT \["/usr/local/bin/terrafarm"\]$'
need 'rm -rf /var/lib/apt/lists/\*'
grep -q '^# .*docker build -f deploy/container/Containerfile' "$C" || fail "no usage in the header"

# Every library the Makefile takes from pkg-config needs its Debian -dev package in the build
# stage, and its run-time package in the final stage.
pkgs=$(sed -n 's/^PKGS *:= *//p' "$ROOT/Makefile")
[ -n "$pkgs" ] || fail "cannot read PKGS from the Makefile"
for p in $pkgs OpenEXR OpenCL; do
    case "$p" in
    inih) dev=libinih-dev run=libinih1 ;;
    libpng) dev=libpng-dev run=libpng16-16 ;;
    libsodium) dev=libsodium-dev run=libsodium23 ;;
    zlib) dev=zlib1g-dev run=zlib1g ;;
    libdeflate) dev=libdeflate-dev run=libdeflate0 ;;
    libmicrohttpd) dev=libmicrohttpd-dev run=libmicrohttpd12 ;;
    jansson) dev=libjansson-dev run=libjansson4 ;;
    sqlite3) dev=libsqlite3-dev run=libsqlite3-0 ;;
    gdal) dev=libgdal-dev run=libgdal32 ;;
    OpenEXR) dev=libopenexr-dev run=libopenexr-3-1-30 ;;
    OpenCL) dev=ocl-icd-opencl-dev run=ocl-icd-libopencl1 ;;
    *) fail "the Makefile links '$p', unknown to this test: add its Debian packages" ;;
    esac
    grep -Eq "(^| )$dev( |$)" "$C" || fail "build stage does not install $dev (for $p)"
    grep -Eq "(^| )$run( |$)" "$C" || fail "run stage does not install $run (for $p)"
done
grep -Eq '(^| )build-essential( |$)' "$C" || fail "no build-essential"
grep -Eq '(^| )pkg-config( |$)' "$C" || fail "no pkg-config"

I=$ROOT/deploy/container/Containerfile.dockerignore
for d in .git build bin; do
    grep -qx "$d" "$I" || fail "$I does not exclude $d"
done

if command -v hadolint >/dev/null 2>&1; then
    hadolint --ignore DL3008 "$C" || fail "hadolint"
fi
echo "deploy_container: ok"
