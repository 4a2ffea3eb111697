#!/bin/sh
# cli_help.sh: every long option a command accepts (its getopt_long table in cli/cmd_*.c) is
# named in that command's --help, so no option is there to be found only in the source.
. "$(dirname "$0")/lib.sh"
e2e_init
missing=
for src in "$TF_ROOT"/cli/cmd_*.c; do
    cmd=$(basename "$src" .c | sed 's/^cmd_//')
    [ "$cmd" = jobs ] && cmd=submit # cmd_jobs.c: submit, jobs, job, cancel ... share one usage
    "$TF_BIN" "$cmd" --help >"$T/help.txt" 2>&1 || fail "terrafarm $cmd --help exited non-zero"
    opts=$(grep -o '{"[a-z0-9-]*", *[a-z_]*_argument' "$src" | sed 's/{"\([a-z0-9-]*\)".*/\1/')
    [ -n "$opts" ] || fail "no long options found in $src (the pattern no longer matches)"
    for o in $opts; do
        [ "$o" = help ] && continue
        grep -q -- "--$o\b" "$T/help.txt" || missing="$missing $cmd:--$o"
    done
done
[ -z "$missing" ] || fail "options missing from --help:$missing"
say "every long option is in its command's --help"
