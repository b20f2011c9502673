#!/usr/bin/env bash
# Build the original implementations the baselines are compared with, outside this project:
# Minguez's MbICP as Player ships it and Censi's CSM, at the commits the README quotes, plus the two
# small drivers of this folder that feed them pairs. Needs git, gcc, cmake and GSL (Debian:
# apt-get install libgsl-dev). Usage: tools/originals/build.sh DIR  (DIR: where to build; not in
# the checkout: their code is theirs and is never committed here).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="${1:?usage: build.sh DIR}"
mkdir -p "$out" && cd "$out"
[ -d player ] || git clone --quiet https://github.com/playerproject/player.git player
git -C player checkout --quiet cb1e0b1349735bcad64eba8846b422f2dc59b768
[ -d csm ] || git clone --quiet https://github.com/AndreaCensi/csm.git csm
git -C csm checkout --quiet dff25579014ee156fe6b1209b56f9f2ee3e56ad1
m=player/server/drivers/position/mbicp
gcc -O2 -o mbicp_pairs -I"$m" "$here/mbicp_pairs.c" "$m/MbICP.c" "$m/calcul.c" "$m/sp_matrix.c" "$m/percolate.c" -lm
cmake -S csm -B csm/build -DCMAKE_BUILD_TYPE=Release >/dev/null && make -C csm/build -j2 >/dev/null
b=csm/build/sm
gcc -O2 -o csm_pairs -Icsm/sm -Icsm/sm/lib -I"$b" "$here/csm_pairs.c" "$b/libcsm-static.a" "$b/lib/options/liboptions.a" \
    "$b/lib/egsl/libegsl.a" "$b/lib/gpc/libgpc.a" "$b/lib/json-c/libjson-c.a" -lgsl -lgslcblas -lm
echo "built $out/mbicp_pairs and $out/csm_pairs"
