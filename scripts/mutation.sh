#!/usr/bin/env bash
# Mutation testing of numeric modules with mutmut 2 (not part of CI: it is long).
#
#   scripts/mutation.sh [--minutes N] [--resume] [--sample N [--seed S]] MODULE [MODULE ...]
#   scripts/mutation.sh [--minutes N] [--resume] [--sample N [--seed S]] MODULE "TESTS" [...]
#   scripts/mutation.sh --report [MODULE ...]          (default: every module run so far)
#   scripts/mutation.sh --show MODULE [STATUS]         (default STATUS: bad_survived)
#   scripts/mutation.sh --list                         (the test selection of each module)
#
# Each MODULE (e.g. mi_displace/core/surfaces.py) is mutated by mutmut in its own scratch
# copy of the committed tree (out/mutation/<module>/, so the working tree is never touched
# and several modules can run side by side from separate shells).  Each mutant runs only
# the module's TESTS (a quoted, space-separated pytest selection; default: the module's
# row in SELECTION below) with `pytest -x`, on llvm_ad_rgb, under `nice -n 15`, without
# bytecode caching (a stale .pyc of the previous mutant would otherwise be tested instead)
# and without the suite's full garbage collection between tests (scripts/mutation_nogc.py).
# Any failing exit status kills the mutant: mutmut 2 counts only status 1 as a failure, so
# a mutant that crashes the test process (a segfault in Dr.Jit from an index out of range)
# or breaks collection (status 2) was reported as a survivor.
# --sample N lists all mutants of each module into mutmut's cache without running them,
# draws N of them uniformly at random (seed S, default 0; scripts/mutation_cache.py
# sample) and runs only those, one by one by id; --report then gives the score on the
# sample with its Wilson 95 % interval and the module's total mutant count.  Modules are
# run in the order given, each its whole sample before the next (breadth first: a second
# call with --resume and a larger N extends each sample, keeping the mutants drawn; the
# seed of a resumed sample is the stored one).
# --resume keeps the module's mutmut cache and refreshes the tree from HEAD (also undoing
# the mutant of a run that was stopped): mutmut keeps the killed mutants, retests the
# survivors and timeouts, then goes on with the untested (commit new tests first); a
# sampled module stays sampled (only its drawn mutants run).
# A mutant's tests time out after 10x the baseline run, at least 10 x MUTATION_MIN_BASELINE
# (default 30) seconds: the baseline runs with Dr.Jit's kernel cache warm, a mutant that
# changes a kernel recompiles it.
# The run stops after --minutes (default 60, shared by all modules of one call) and
# prints per module: mutants, killed, survived, timed out, untested, score, run time.
# --show prints each mutant's changed line (scripts/mutation_cache.py).  Never run
# `mutmut show`/`apply` in a scratch copy while its run is going: they re-map mutmut's
# line records against the (then mutated) file, and the run dies ("Attribute Mutant.line
# is required") and hangs.  Results are in docs/testing.md.
# Needs `pip install "mutmut<3"` (mutmut 3 forks after Dr.Jit started its thread pool).
set -euo pipefail
cd "$(dirname "$0")/.."

# The test selection of each measured module: the tests that exercise it, kept small so
# that one mutant runs in seconds.
declare -A SELECTION=(
  [mi_displace/evaluate/metrics.py]="tests/evaluate/test_metrics.py"
  [mi_displace/core/heightfield.py]="tests/core/test_heightfield.py"
  [mi_displace/core/surfaces.py]="tests/core/test_surfaces.py"
  [mi_displace/core/tessellate.py]="tests/core/test_tessellate.py tests/core/test_core_mutants.py"
  [mi_displace/ddm/mapping.py]="tests/ddm/test_ddm_mapping.py tests/ddm/test_ddm_orientation.py"
  [mi_displace/vdm/mesh_curvature.py]="tests/vdm/test_vdm_mesh_curvature.py tests/vdm/test_vdm_unseen.py::test_per_corner_normals_give_the_torus_curvature tests/vdm/test_vdm_unseen.py::test_zero_curvature_on_a_curved_mesh_warns"
  [mi_displace/vdm/table.py]="tests/vdm/test_vdm_table.py"
  [mi_displace/vdm/build.py]="tests/vdm/test_vdm_build.py tests/vdm/test_vdm_table.py::test_bad_heights_and_spec tests/vdm/test_vdm_compression.py tests/vdm/test_vdm_cache.py"
  [mi_displace/vdm/compression.py]="tests/vdm/test_vdm_compression.py"
  [mi_displace/vdm/curvature.py]="tests/vdm/test_vdm_curvature.py"
  [mi_displace/vdm/frame.py]="tests/vdm/test_vdm_frame.py tests/vdm/test_vdm_baselines.py tests/vdm/test_vdm_unseen.py"
  [mi_displace/vdm/lookup.py]="tests/vdm/test_vdm_lookup.py tests/vdm/test_vdm_unseen.py tests/vdm/test_vdm_plugin.py::test_silhouettes_and_relief_follow_true_displacement tests/vdm/test_vdm_plugin.py::test_grazing_views_and_deep_relief tests/vdm/test_vdm_plugin.py::test_curvature_beyond_range_is_clamped_and_counted tests/vdm/test_vdm_plugin.py::test_depth_zero_is_the_nested_material"
  [mi_displace/vdm/steps.py]="tests/vdm/test_vdm_steps.py tests/vdm/test_vdm_unseen.py tests/vdm/test_vdm_plugin.py::test_silhouettes_and_relief_follow_true_displacement tests/vdm/test_vdm_plugin.py::test_grazing_views_and_deep_relief tests/vdm/test_vdm_plugin.py::test_curvature_beyond_range_is_clamped_and_counted tests/vdm/test_vdm_plugin.py::test_depth_zero_is_the_nested_material"
  [mi_displace/core/dicing.py]="tests/core/test_dicing.py"
  [mi_displace/bake/trace.py]="tests/bake/test_bake_extremes.py tests/bake/test_bake_naive.py tests/bake/test_bake_cage_multistep.py::test_cage_offset_measures_along_the_cage tests/bake/test_bake_cage_multistep.py::test_cage_rays_that_miss_are_classified tests/bake/test_bake_cage_multistep.py::test_tilted_cage_direction_round_trip tests/bake/test_bake_mikktspace.py tests/bake/test_bake_mutants.py"
  [mi_displace/bake/baker.py]="tests/bake/test_bake_extremes.py tests/bake/test_bake_sphere.py tests/bake/test_bake_cli.py tests/bake/test_bake_padding_tangent.py tests/bake/test_bake_mutants.py"
  [mi_displace/bake/restore.py]="tests/bake/test_bake_restore.py tests/bake/test_bake_seams_holes.py tests/bake/test_bake_plugin.py::test_restored_shape_matches_restore tests/bake/test_bake_mutants.py"
  [mi_displace/bake/formats.py]="tests/bake/test_bake_formats.py tests/bake/test_bake_faults.py tests/bake/test_bake_sphere.py tests/bake/test_bake_mutants.py"
  [mi_displace/bake/uv_raster.py]="tests/bake/test_bake_extremes.py tests/bake/test_bake_naive.py tests/bake/test_bake_sphere.py::test_map_matches_function tests/bake/test_bake_mutants.py"
  [mi_displace/bake/mikktspace.py]="tests/bake/test_bake_mikktspace.py tests/bake/test_bake_padding_tangent.py tests/bake/test_bake_mutants.py"
  [mi_displace/bake/levels.py]="tests/bake/test_bake_levels.py tests/bake/test_bake_mutants.py"
  [mi_displace/volume/maps.py]="tests/volume/test_volume_maps.py tests/volume/test_volume_mutants.py"
  [mi_displace/volume/displacement.py]="tests/volume/test_volume_maps.py tests/volume/test_volume_normals.py tests/volume/test_volume_mutants.py"
  [mi_displace/volume/field.py]="tests/volume/test_volume_normals.py tests/volume/test_volume_albedo.py tests/volume/test_volume_render.py tests/volume/test_volume_mutants.py"
  [mi_displace/slicing/geometry.py]="tests/slicing/test_slicing.py tests/slicing/test_slicing_mutants.py"
  [mi_displace/slicing/depth_object.py]="tests/slicing/test_depth_object.py tests/slicing/test_slicing_mutants.py"
  [mi_displace/ddm/tiles.py]="tests/ddm/test_ddm_tiles.py tests/ddm/test_ddm_mutants.py"
  [mi_displace/ddm/base_maps.py]="tests/ddm/test_ddm_base_maps.py tests/ddm/test_ddm_mutants.py"
  [mi_displace/ddm/model.py]="tests/ddm/test_ddm_mapping.py tests/ddm/test_ddm_base_maps.py tests/ddm/test_ddm_mutants.py"
  [mi_displace/ddm/charts.py]="tests/ddm/test_ddm_charts.py tests/ddm/test_ddm_polygonal.py tests/ddm/test_ddm_mutants.py"
  [mi_displace/ddm/mesh_base.py]="tests/ddm/test_ddm_polygonal.py tests/ddm/test_ddm_charts.py tests/ddm/test_ddm_mutants.py"
  [mi_displace/ddm/layout.py]="tests/ddm/test_ddm_layout.py tests/ddm/test_ddm_mutants.py"
  [mi_displace/ddm/footprint.py]="tests/ddm/test_ddm_footprint.py tests/ddm/test_ddm_mutants.py"
  [mi_displace/core/bezier.py]="tests/ddm/test_ddm_bezier.py tests/core/test_core_mutants.py"
  [mi_displace/core/thickness.py]="tests/core/test_thickness.py tests/core/test_core_mutants.py"
)

root=$PWD
export PYTHONDONTWRITEBYTECODE=1 MI_DISPLACE_TEST_VARIANTS=llvm_ad_rgb PATH="$root/.venv/bin:$PATH" \
    PYTHONPATH="$root/scripts"
dir_of() { echo "out/mutation/$(echo "${1#mi_displace/}" | tr / _ | sed 's/\.py$//')"; }

minutes=60 resume=0 report=0 sample=0 seed= min_baseline=${MUTATION_MIN_BASELINE:-30}
while [ $# -gt 0 ]; do
  case $1 in
    --minutes) minutes=$2; shift 2 ;;
    --resume) resume=1; shift ;;
    --sample) sample=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --report) report=1; shift ;;
    --show) exec python scripts/mutation_cache.py show "$(dir_of "$2")" "${3:-bad_survived}" ;;
    --list) for m in "${!SELECTION[@]}"; do echo "$m: ${SELECTION[$m]}"; done | sort; exit 0 ;;
    *) break ;;
  esac
done

modules=()
declare -A TESTS
while [ $# -gt 0 ]; do
  module=$1; shift
  if [ $# -gt 0 ] && [[ $1 == tests/* ]]; then TESTS[$module]=$1; shift
  elif [ -n "${SELECTION[$module]:-}" ]; then TESTS[$module]=${SELECTION[$module]}
  elif [ $report = 0 ]; then echo "no test selection for $module: add it to SELECTION" >&2; exit 2
  fi
  modules+=("$module")
done
if [ $report = 1 ] && [ ${#modules[@]} = 0 ]; then
  for d in out/mutation/*/MODULE; do [ -e "$d" ] && modules+=("$(cat "$d")"); done
fi
[ ${#modules[@]} -gt 0 ] || { sed -n 2,40p "$0"; exit 2; }

untested() {  # the untested mutants of scratch copy $1 (of its sample, if it has one)
  python -c "import sqlite3, sys; sys.path.insert(0, 'scripts'); import mutation_cache as m
from pathlib import Path; w = Path('$1'); s = m.read_sample(w)
ids = {r[0] for r in sqlite3.connect(w / '.mutmut-cache').execute(
    \"select id from Mutant where status = 'untested'\")}
print(*(i for i in (s[1] if s else sorted(ids)) if i in ids))"
}

if [ $report = 0 ]; then
  deadline=$(( $(date +%s) + 60 * minutes ))
  for module in "${modules[@]}"; do
    work=$(dir_of "$module") stored=
    if [ $resume = 1 ] && [ -e "$work/.mutmut-cache" ]; then
      stored=$(sed -n '1s/^seed //p' "$work/SAMPLE" 2>/dev/null || true)
      if [ -n "$stored" ] && [ -n "$seed" ] && [ "$seed" != "$stored" ]; then
        echo "$module: its sample was drawn with seed $stored, not $seed" >&2; exit 2
      fi
      rm -rf "$work/tests" && git archive HEAD | tar -x -C "$work"
      # retest the survivors and timeouts even where the tests did not change (a new runner)
      python -c "import sqlite3; db = sqlite3.connect('$work/.mutmut-cache'); db.execute(
          \"update Mutant set status = 'untested' where status in ('bad_survived', 'bad_timeout')\"); db.commit()"
    else
      rm -rf "$work" && mkdir -p "$work"
      git archive HEAD | tar -x -C "$work"
      echo 0 > "$work/SECONDS"
    fi
    echo "$module" > "$work/MODULE"
    echo "${TESTS[$module]}" > "$work/TESTS"
    # mutmut kills a mutant's tests after 10x the baseline run, which ran with Dr.Jit's
    # kernel cache warm; a mutant that changes a kernel recompiles it, and on the loaded
    # machine that took longer (curvature.py: 74 s): a floor on the baseline (mutmut reads
    # this hook from the working directory) keeps such mutants from counting as timeouts
    cat > "$work/mutmut_config.py" <<PY
def pre_mutation(context):
    context.config.baseline_time_elapsed = max(context.config.baseline_time_elapsed, $min_baseline)
PY
    runner="bash -c 'python -m pytest -x -q -p no:cacheprovider -p mutation_nogc ${TESTS[$module]} || exit 1'"
    if [ "$sample" -gt 0 ]; then
      [ -n "$stored" ] || python scripts/mutation_cache.py register "$work"
      python scripts/mutation_cache.py sample "$work" "$sample" "${stored:-${seed:-0}}"
    fi
    left=$(( deadline - $(date +%s) ))
    [ "$left" -gt 60 ] || { echo "time is up before $module"; break; }
    echo "== $module (${TESTS[$module]}), $left s left"
    start=$(date +%s)
    if [ ! -e "$work/SAMPLE" ]; then
      (cd "$work" && timeout "$left" nice -n 15 mutmut run --paths-to-mutate "$module" \
          --tests-dir tests --simple-output --no-progress --runner "$runner" \
          > mutmut.log 2>&1) || true
    fi
    # a sampled module runs its mutants by id; so do, after a full run, those of a line that
    # also occurs earlier in the file (`periodic_u = True` in three classes): mutmut 2 looks
    # up the cached status of a mutant by its line's text, so they are never run
    for pk in $(untested "$work"); do
      [ $(( deadline - $(date +%s) )) -gt 60 ] || break
      (cd "$work" && timeout $(( deadline - $(date +%s) )) nice -n 15 mutmut run "$pk" \
          --paths-to-mutate "$module" --tests-dir tests --simple-output --no-progress \
          --runner "$runner" >> mutmut.log 2>&1) || true
    done
    echo $(( $(cat "$work/SECONDS") + $(date +%s) - start )) > "$work/SECONDS"
    grep -qs "^Traceback" "$work/mutmut.log" && echo "mutmut failed: see $work/mutmut.log" >&2
  done
fi

dirs=()
for module in "${modules[@]}"; do
  work=$(dir_of "$module")
  [ -e "$work/.mutmut-cache" ] && dirs+=("$work") || echo "$module: not run" >&2
done
[ ${#dirs[@]} = 0 ] || python scripts/mutation_cache.py report "${dirs[@]}"
