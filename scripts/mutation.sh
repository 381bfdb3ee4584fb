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

# The edge-case tests of each package (written to kill mutants that survived the rest of its
# tests), in the test modules of their subjects; every module of the package runs them (a
# test named both whole and by its file runs once).
edges_core="tests/ddm/test_ddm_bezier.py::test_teapot_derivatives_along_v_match_finite_differences \
  tests/ddm/test_ddm_bezier.py::test_teapot_extent_is_the_longest_isoparametric_curve \
  tests/ddm/test_ddm_bezier.py::test_teapot_curvature_bounds_are_the_extremes_on_a_finer_grid \
  tests/core/test_thickness.py::test_crossing_check_without_displacement_or_vertices \
  tests/core/test_thickness.py::test_displacement_of_exactly_the_thickness_reaches_but_does_not_cross \
  tests/core/test_thickness.py::test_outward_rays_use_their_own_facing \
  tests/core/test_thickness.py::test_crossing_rays_report_the_uv_of_what_they_hit \
  tests/core/test_tessellate.py::test_group_mean_of_scalars_and_vectors \
  tests/core/test_tessellate.py::test_vertex_frames_weight_the_triangles_by_area \
  tests/core/test_tessellate.py::test_zero_vertex_normals_fall_back_to_the_tangent_frame"
edges_slicing="tests/slicing/test_slicing.py::test_a_plane_base_is_boxed_by_twelve_wall_triangles \
  tests/slicing/test_slicing.py::test_base_coordinates_invert_the_parametrisation \
  tests/slicing/test_slicing.py::test_base_tangents_are_dS_du_and_dS_dv \
  tests/slicing/test_slicing.py::test_projected_size_through_a_thin_lens_is_the_pinhole_one \
  tests/slicing/test_depth_object.py::test_skip_leaves_an_empty_cell_a_hair_before_its_far_face \
  tests/slicing/test_depth_object.py::test_images_of_different_sizes_are_named_in_the_message \
  tests/slicing/test_depth_object.py::test_default_cube_holds_the_object_with_its_margin \
  tests/slicing/test_depth_object.py::test_without_normal_images_the_best_facing_cube_face_is_the_normal"
edges_volume="tests/volume/test_volume_maps.py::test_the_support_box_holds_every_displacement \
  tests/volume/test_volume_maps.py::test_peel_is_continuous_across_the_cut_plane_beyond_the_hinge \
  tests/volume/test_volume_maps.py::test_placement_messages_name_the_parameter_whole \
  tests/volume/test_volume_maps.py::test_texture_bytes_count_the_non_zero_channels \
  tests/volume/test_volume_maps.py::test_jacobian_of_an_obliquely_placed_map_matches_finite_differences \
  tests/volume/test_volume_maps.py::test_peel_skips_its_undisplaced_cells \
  tests/volume/test_volume_maps.py::test_world_box_of_an_uneven_box \
  tests/volume/test_volume_maps.py::test_alpha_gradient_texture_matches_finite_differences \
  tests/volume/test_volume_maps.py::test_jacobian_along_every_local_axis_of_the_seam \
  tests/volume/test_volume_maps.py::test_set_moves_the_map_and_the_proxy_holds_matter_moved_down \
  tests/volume/test_volume_maps.py::test_precomputed_composition_reads_one_composite_d_k \
  tests/volume/test_volume_maps.py::test_sampled_map_resolution_error_names_the_d_k \
  tests/volume/test_volume_maps.py::test_placement_vector_to_world_is_the_linear_part \
  tests/volume/test_volume_maps.py::test_changed_rebuilds_the_precomputed_composite \
  tests/volume/test_volume_normals.py::test_where_the_field_is_flat_every_normal_is_the_fallback \
  tests/volume/test_volume_normals.py::test_a_lookup_without_the_alpha_gradient_gives_the_same_blend_normals \
  tests/volume/test_volume_normals.py::test_blend_is_eq_7_between_the_jacobian_and_the_cut_normal \
  tests/volume/test_volume_render.py::test_majorant_is_the_tight_bound_of_sigma_t \
  tests/volume/test_volume_render.py::test_parameter_edges_and_messages"
edges_ddm="tests/ddm/test_ddm_tiles.py::test_stadium_is_a_closed_curve_of_evenly_spaced_distinct_points \
  tests/ddm/test_ddm_tiles.py::test_chain_links_have_their_stated_sizes \
  tests/ddm/test_ddm_tiles.py::test_plate_is_an_n_by_n_grid_over_the_unit_square \
  tests/ddm/test_ddm_tiles.py::test_hexagon_covers_its_hexagon_once_and_zero_normals_become_up \
  tests/ddm/test_ddm_base_maps.py::test_clamped_count_on_open_axes_takes_the_nearest_texel \
  tests/ddm/test_ddm_base_maps.py::test_map_error_skips_every_lookup_that_touches_an_invalid_texel \
  tests/ddm/test_ddm_base_maps.py::test_geometry_image_bytes_and_resolution_halving_gives_an_int \
  tests/ddm/test_ddm_base_maps.py::test_diffusion_takes_the_first_texel_as_a_source \
  tests/ddm/test_ddm_base_maps.py::test_prune_reads_the_tile_footprint_in_v \
  tests/ddm/test_ddm_base_maps.py::test_prune_grows_the_footprint_by_one_texel_and_auto_starts_at_a_power_of_two \
  tests/ddm/test_ddm_footprint.py::test_pixels_per_uv_is_the_projected_step_of_a_pinhole \
  tests/ddm/test_ddm_footprint.py::test_orthographic_visibility_needs_front_and_frustum \
  tests/ddm/test_ddm_footprint.py::test_auto_resolution_on_the_plane \
  tests/ddm/test_ddm_footprint.py::test_weighted_quantile_ends \
  tests/ddm/test_ddm_footprint.py::test_footprint_samples_of_mesh_and_analytic_bases \
  tests/ddm/test_ddm_footprint.py::test_perspective_visibility_needs_front_and_both_frame_axes \
  tests/ddm/test_ddm_layout.py::test_one_cell_layout_and_one_entry_pattern \
  tests/ddm/test_ddm_layout.py::test_hex_rows_alternate_their_shift_and_gaps_shrink_hexagons \
  tests/ddm/test_ddm_layout.py::test_layout_messages_and_the_default_seed \
  tests/ddm/test_ddm_mapping.py::test_model_size_check_for_one_column_and_no_refit_without_auto \
  tests/ddm/test_ddm_mapping.py::test_model_w_max_rule_and_memory_ratio \
  tests/ddm/test_ddm_mapping.py::test_model_stats_clamped_mask_and_fold_message \
  tests/ddm/test_ddm_charts.py::test_tile_reach_is_the_cell_or_the_overhang \
  tests/ddm/test_ddm_charts.py::test_chart_maps_bytes_and_stats_and_pruned_count \
  tests/ddm/test_ddm_charts.py::test_chart_maps_lookup_reproduces_every_stored_texel \
  tests/ddm/test_ddm_charts.py::test_chart_map_error_is_zero_on_a_flat_mesh_and_falls_with_resolution \
  tests/ddm/test_ddm_polygonal.py::test_mesh_curvature_bound_is_the_normal_turn_per_length \
  tests/ddm/test_ddm_polygonal.py::test_mesh_sample_is_differentiable_in_uv \
  tests/ddm/test_ddm_polygonal.py::test_mesh_curvature_bound_reads_every_edge_of_a_triangle \
  tests/ddm/test_ddm_polygonal.py::test_mesh_normal_derivatives_match_finite_differences_inside_a_face"
edges_bake="tests/bake/test_bake_cage_multistep.py::test_cage_ray_flags_a_second_crossing_and_only_that \
  tests/bake/test_bake_cage_multistep.py::test_cage_tilted_along_the_bitangent_restores \
  tests/bake/test_bake_extremes.py::test_dual_depth_is_the_next_surface_behind \
  tests/bake/test_bake_extremes.py::test_without_meminfo_a_default_bake_still_fits \
  tests/bake/test_bake_extremes.py::test_a_low_poly_a_fifth_of_the_diagonal_away_is_refused \
  tests/bake/test_bake_extremes.py::test_memory_refusal_message_whole \
  tests/bake/test_bake_extremes.py::test_a_low_poly_eleven_times_larger_is_refused \
  tests/bake/test_bake_uv_raster.py::test_uv_warning_is_the_whole_sentence \
  tests/bake/test_bake_uv_raster.py::test_texel_value_is_the_mean_over_its_aa_grid \
  tests/bake/test_bake_uv_raster.py::test_conservative_band_texels_take_a_chart_point_of_their_own_footprint \
  tests/bake/test_bake_uv_raster.py::test_an_isolated_sliver_chart_gets_no_texels_and_is_counted \
  tests/bake/test_bake_uv_raster.py::test_overlap_is_measured_at_most_at_256 \
  tests/bake/test_bake_uv_raster.py::test_overlap_count_is_the_texel_centres_inside_both_triangles \
  tests/bake/test_bake_formats.py::test_unit_vectors_encode_as_documented_and_pngs_are_linear \
  tests/bake/test_bake_formats.py::test_missing_map_message_names_the_file \
  tests/bake/test_bake_formats.py::test_quantised_sidecars_record_their_bit_depth \
  tests/bake/test_bake_formats.py::test_a_constant_map_round_trips_in_every_format \
  tests/bake/test_bake_restore.py::test_restored_mesh_saves_as_obj_and_ply \
  tests/bake/test_bake_restore.py::test_dropped_holes_are_reported \
  tests/bake/test_bake_restore.py::test_restore_refuses_a_boolean_or_fractional_split \
  tests/bake/test_bake_restore.py::test_restore_of_another_low_poly_message_whole \
  tests/bake/test_bake_restore.py::test_map_sidecars_name_the_low_poly_written_beside_them \
  tests/bake/test_bake_seams_holes.py::test_void_texels_of_a_closed_low_poly_take_their_neighbours_displacement \
  tests/bake/test_bake_sphere.py::test_object_normals_of_a_sphere_are_radial \
  tests/bake/test_bake_levels.py::test_orthographic_footprint_and_levels \
  tests/bake/test_bake_levels.py::test_perspective_footprint_of_a_wide_film \
  tests/bake/test_bake_levels.py::test_only_edges_inside_the_view_cone_count \
  tests/bake/test_bake_levels.py::test_footprint_of_a_thin_lens_is_the_pinhole_one \
  tests/bake/test_bake_mikktspace.py::test_decode_tangent_map_gives_the_object_normals \
  tests/bake/test_bake_mikktspace.py::test_degenerate_triangles_copy_the_tangent_of_their_vertex \
  tests/bake/test_bake_padding_tangent.py::test_padded_texels_are_counted \
  tests/bake/test_bake_padding_tangent.py::test_texels_beyond_the_padding_hold_plus_z_normals"

# The test selection of each measured module: the tests that exercise it, kept small so
# that one mutant runs in seconds.
declare -A SELECTION=(
  [mi_displace/evaluate/metrics.py]="tests/evaluate/test_metrics.py"
  [mi_displace/core/heightfield.py]="tests/core/test_heightfield.py"
  [mi_displace/core/surfaces.py]="tests/core/test_surfaces.py"
  [mi_displace/core/tessellate.py]="tests/core/test_tessellate.py ${edges_core}"
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
  [mi_displace/bake/trace.py]="tests/bake/test_bake_extremes.py tests/bake/test_bake_naive.py tests/bake/test_bake_cage_multistep.py::test_cage_offset_measures_along_the_cage tests/bake/test_bake_cage_multistep.py::test_cage_rays_that_miss_are_classified tests/bake/test_bake_cage_multistep.py::test_tilted_cage_direction_round_trip tests/bake/test_bake_mikktspace.py ${edges_bake}"
  [mi_displace/bake/baker.py]="tests/bake/test_bake_extremes.py tests/bake/test_bake_sphere.py tests/bake/test_bake_cli.py tests/bake/test_bake_padding_tangent.py ${edges_bake}"
  [mi_displace/bake/restore.py]="tests/bake/test_bake_restore.py tests/bake/test_bake_seams_holes.py tests/bake/test_bake_plugin.py::test_restored_shape_matches_restore ${edges_bake}"
  [mi_displace/bake/formats.py]="tests/bake/test_bake_formats.py tests/bake/test_bake_faults.py tests/bake/test_bake_sphere.py ${edges_bake}"
  [mi_displace/bake/uv_raster.py]="tests/bake/test_bake_extremes.py tests/bake/test_bake_naive.py tests/bake/test_bake_sphere.py::test_map_matches_function ${edges_bake}"
  [mi_displace/bake/mikktspace.py]="tests/bake/test_bake_mikktspace.py tests/bake/test_bake_padding_tangent.py ${edges_bake}"
  [mi_displace/bake/levels.py]="tests/bake/test_bake_levels.py ${edges_bake}"
  [mi_displace/volume/maps.py]="tests/volume/test_volume_maps.py ${edges_volume}"
  [mi_displace/volume/displacement.py]="tests/volume/test_volume_maps.py tests/volume/test_volume_normals.py ${edges_volume}"
  [mi_displace/volume/field.py]="tests/volume/test_volume_normals.py tests/volume/test_volume_albedo.py tests/volume/test_volume_render.py ${edges_volume}"
  [mi_displace/slicing/geometry.py]="tests/slicing/test_slicing.py ${edges_slicing}"
  [mi_displace/slicing/depth_object.py]="tests/slicing/test_depth_object.py ${edges_slicing}"
  [mi_displace/ddm/tiles.py]="tests/ddm/test_ddm_tiles.py ${edges_ddm}"
  [mi_displace/ddm/base_maps.py]="tests/ddm/test_ddm_base_maps.py ${edges_ddm}"
  [mi_displace/ddm/model.py]="tests/ddm/test_ddm_mapping.py tests/ddm/test_ddm_base_maps.py ${edges_ddm}"
  [mi_displace/ddm/charts.py]="tests/ddm/test_ddm_charts.py tests/ddm/test_ddm_polygonal.py ${edges_ddm}"
  [mi_displace/ddm/mesh_base.py]="tests/ddm/test_ddm_polygonal.py tests/ddm/test_ddm_charts.py ${edges_ddm}"
  [mi_displace/ddm/layout.py]="tests/ddm/test_ddm_layout.py ${edges_ddm}"
  [mi_displace/ddm/footprint.py]="tests/ddm/test_ddm_footprint.py ${edges_ddm}"
  [mi_displace/core/bezier.py]="tests/ddm/test_ddm_bezier.py ${edges_core}"
  [mi_displace/core/thickness.py]="tests/core/test_thickness.py ${edges_core}"
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
