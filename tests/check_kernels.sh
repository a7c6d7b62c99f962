#!/bin/sh
# Compiles every OpenCL program heatvox builds, assembled as the library
# assembles it (kernels/common.cl first, then the module's sources, with its
# build options; the modules as the code describes them), offline with clang as strict OpenCL C 1.2 and as OpenCL C
# 3.0, with and without fp64: -Werror -pedantic, so that what NVIDIA's
# compiler refuses (variadic macros, extensions) fails here, on a machine
# without a GPU. Usage: check_kernels.sh OUTDIR [CLANG]
set -u
out=${1:?usage: check_kernels.sh OUTDIR [CLANG]}
cc=${2:-clang-14}
here=$(dirname "$0")/..
mkdir -p "$out"
wg=$(sed -n 's/^#define HV_CL_WG \([0-9]*\).*/\1/p' "$here/src/cl/cl_core.h")
rb=$(sed -n 's/^#define HV_CL_RED_BLOCK \([0-9]*\).*/\1/p' "$here/src/cl/cl_core.h")
[ -n "$wg" ] && [ -n "$rb" ] || { echo "check_kernels: HV_CL_WG or HV_CL_RED_BLOCK not found"; exit 1; }

# name:sources after common.cl[:fp64], one line per module, read from the
# code's hv_cl_module descriptions (tests/cl_programs.py); "fp64" where the
# module is built only with fp64.
programs=$(python3 "$here/tests/cl_programs.py" "$here") || {
    echo "check_kernels: the programs could not be read from src/"
    exit 1
}

# Every kernel file is in some program.
for f in "$here"/kernels/*.cl; do
    k=$(basename "$f" .cl)
    [ "$k" = common ] && continue
    echo "$programs" | grep -Eq "[:,]$k(,|:|\$)" || {
        echo "check_kernels: kernels/$k.cl is in no program of the code"
        exit 1
    }
done

n=0 bad=0
for p in $programs; do
    name=${p%%:*}
    rest=${p#*:}
    srcs=${rest%%:*}
    only64=""
    [ "$rest" != "$srcs" ] && only64=${rest#*:}
    file=$out/$name.cl
    cat "$here/kernels/common.cl" >"$file"
    for s in $(echo "$srcs" | tr , ' '); do
        cat "$here/kernels/$s.cl" >>"$file"
    done
    for prec in fp64 fp32; do
        [ "$prec" = fp32 ] && [ "$only64" = fp64 ] && continue
        for std in CL1.2 CL3.0; do
            defs="-DHV_WG=$wg -DHV_RED_BLOCK=$rb"
            ext=""
            if [ "$prec" = fp64 ]; then
                defs="$defs -DHV_FP64=1"
                [ "$std" = CL3.0 ] && ext="-Xclang -cl-ext=+cl_khr_fp64,+__opencl_c_fp64"
            else
                ext="-Xclang -cl-ext=-cl_khr_fp64,-__opencl_c_fp64"
            fi
            log=$out/$name.$prec.$std.log
            n=$((n + 1))
            if "$cc" -x cl -cl-std="$std" -Xclang -finclude-default-header $ext $defs \
                -Werror -pedantic -fsyntax-only "$file" >"$log" 2>&1; then
                echo "  $name ($prec, $std): ok"
            else
                bad=$((bad + 1))
                echo "  $name ($prec, $std): FAILED"
                head -n 20 "$log" | sed 's/^/    /'
            fi
        done
    done
done
# The example programs' own kernels (tools/examples/*_cl.c: the C string
# `kernels`), strict OpenCL C 1.2 and 3.0 as a user's would be built.
for ex in "$here"/tools/examples/*_cl.c; do
    [ -f "$ex" ] || continue
    name=$(basename "$ex" .c)
    file=$out/example_$name.cl
    python3 - "$ex" "$file" <<'PY' || { echo "check_kernels: no kernels string in $ex"; exit 1; }
import ast, re, sys
src = open(sys.argv[1]).read()
m = re.search(r'static const char \*kernels =(.*?);\n', src, re.S)
if not m:
    sys.exit(1)
parts = re.findall(r'"(?:[^"\\]|\\.)*"', m.group(1))
open(sys.argv[2], "w").write("".join(ast.literal_eval(p) for p in parts))
PY
    for std in CL1.2 CL3.0; do
        n=$((n + 1))
        log=$out/example_$name.$std.log
        if "$cc" -x cl -cl-std="$std" -Xclang -finclude-default-header -Werror -pedantic \
            -fsyntax-only "$file" >"$log" 2>&1; then
            echo "  example $name ($std): ok"
        else
            bad=$((bad + 1))
            echo "  example $name ($std): FAILED"
            head -n 20 "$log" | sed 's/^/    /'
        fi
    done
done
# make check reads this line as it reads Check's.
echo "$(((n - bad) * 100 / n))%: Checks: $n, Failures: $bad, Errors: 0"
if [ "$bad" -ne 0 ]; then
    echo "check_kernels: $bad of $n compiles failed (logs in $out)"
    exit 1
fi
echo "check_kernels: $n compiles of $(echo "$programs" | wc -l) programs and the examples', strict OpenCL C 1.2 and 3.0"
