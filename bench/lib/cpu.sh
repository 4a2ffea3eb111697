# bench/lib/cpu.sh: the machine a benchmark ran on, for the first lines of its report (sourced
# by the bench/*.sh scripts; these machines differ, so every figure names its CPU and ISA).
#   bench_isa        the vector ISAs of the CPU that matter here: "avx512f avx2 fma avx sse4_2",
#                    those it has, in that order
#   bench_cpu_line   "cpu: MODEL, N cores, isa: ..."

bench_isa() {
    _flags=" $(grep -m1 '^flags' /proc/cpuinfo || true) "
    _isa=""
    for _f in avx512f avx2 fma avx sse4_2; do
        case "$_flags" in *" $_f "*) _isa="$_isa $_f" ;; esac
    done
    echo "${_isa# }"
}

bench_cpu_line() {
    echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//'), $(nproc) cores, isa: $(bench_isa)"
}
