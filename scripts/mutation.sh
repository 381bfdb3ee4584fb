#!/usr/bin/env bash
# Mutation testing of numeric modules with mutmut 2 (not part of CI: it is long).
#
#   scripts/mutation.sh [--minutes N] MODULE TESTS [MODULE TESTS ...]
#   scripts/mutation.sh --minutes 60 mi_displace/evaluate/metrics.py tests/evaluate/test_metrics.py
#
# Each MODULE is mutated by mutmut in a scratch copy of the committed tree (out/mutation/,
# so the working tree is never touched), and each mutant runs only its TESTS (a quoted,
# space-separated list) with `pytest -x`, on llvm_ad_rgb, without bytecode caching (a stale
# .pyc of the previous mutant would otherwise be tested instead).  The run stops after
# --minutes (default 60) and reports per module: killed, survived, timed out, untested.
# Survivors: `cd out/mutation && mutmut show ID`.  Results are in docs/testing.md.
# Needs `pip install "mutmut<3"` (mutmut 3 forks after Dr.Jit started its thread pool).
set -euo pipefail
cd "$(dirname "$0")/.."
minutes=60
if [ "${1:-}" = "--minutes" ]; then minutes=$2; shift 2; fi
[ $# -ge 2 ] || { sed -n 2,14p "$0"; exit 2; }
root=$PWD
work=out/mutation
rm -rf "$work" && mkdir -p "$work"
git archive HEAD | tar -x -C "$work"
cd "$work"
export PYTHONDONTWRITEBYTECODE=1 MI_DISPLACE_TEST_VARIANTS=llvm_ad_rgb PATH="$root/.venv/bin:$PATH"
deadline=$(( $(date +%s) + 60 * minutes ))
while [ $# -ge 2 ]; do
  module=$1 tests=$2; shift 2
  left=$(( deadline - $(date +%s) ))
  [ "$left" -gt 60 ] || { echo "time is up before $module"; break; }
  echo "== $module ($tests), $left s left"
  timeout "$left" mutmut run --paths-to-mutate "$module" --tests-dir tests --simple-output \
      --no-progress --runner "python -m pytest -x -q -p no:cacheprovider $tests" > /dev/null || true
done
python - <<'EOF'
import sqlite3
db = sqlite3.connect(".mutmut-cache")
rows = db.execute("select SourceFile.filename, Mutant.status, count(*) from Mutant "
                  "join Line on Mutant.line = Line.id join SourceFile on Line.sourcefile = "
                  "SourceFile.id group by 1, 2").fetchall()
files = sorted({r[0] for r in rows})
print("| module | killed | survived | timeout | untested | score ((killed + timeout) / tested) |")
print("|---|---|---|---|---|---|")
for f in files:
    n = {s: c for name, s, c in rows if name == f}
    # "suspicious" = killed, but slowly; a timeout (e.g. an endless loop) counts as detected
    killed = n.get("ok_killed", 0) + n.get("ok_suspicious", 0)
    survived, timeout, untested = n.get("bad_survived", 0), n.get("bad_timeout", 0), n.get("untested", 0)
    tested = killed + survived + timeout
    score = f"{100 * (killed + timeout) / tested:.0f} %" if tested else "-"
    print(f"| {f} | {killed} | {survived} | {timeout} | {untested} | {score} |")
EOF
