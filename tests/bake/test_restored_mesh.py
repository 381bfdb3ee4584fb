"""The restored shape's builder (mi_displace.bake.restored_mesh) used alone, without a mi.Mesh:
a plane baked 0.02 above its low-poly restores at that height in world space, and an edit of
the texels re-displaces it on the same topology."""
import mitsuba as mi
import numpy as np
from bake_meshes import plane

from mi_displace.bake.baker import bake
from mi_displace.bake.restored_mesh import RestoredSurface


def test_restored_surface_builds_and_redisplaces_in_world_space(variant_llvm, tmp_path):
    bake(plane(z=0.02, n=8), plane(n=2), res=8, max_distance=0.05, pad=2, out_dir=tmp_path,
         map_formats=["d16"])
    values = {"map": str(tmp_path / "d16.png"), "low": None, "levels": 2, "split": None,
              "dicing_rate": 1.0, "keep_holes": True}
    surface = RestoredSurface(values, [], mi.ScalarTransform4f().translate([0, 0, 1]))
    built = surface.build_mesh()
    p = np.asarray(built.positions).reshape(-1, 3)
    assert np.all(np.isfinite(p)) and np.all(np.isfinite(np.asarray(built.normals)))
    # 2 rounds of 1 -> 4 on the 8 triangles of a 2 x 2 plane: 128 faces on a 9 x 9 grid
    assert built.face_count == built.stats["faces"] == 8 * 4 ** 2 == len(np.asarray(built.faces)) // 3
    assert built.vertex_count == len(p) == 9 * 9
    np.testing.assert_allclose(p[:, 2], 1.02, atol=1e-4)      # the high plane, moved up by 1
    assert (p[:, :2].min(), p[:, :2].max()) == (0, 1)
    assert surface.owns(["displacement"]) and not surface.owns(["vertex_positions"])
    surface.displacement.array[:] = 0   # (an edit through mi.traverse writes in place like this)
    edited = surface.edit(["displacement"])
    assert edited.faces is None and edited.texcoords is None and edited.stats is None
    np.testing.assert_allclose(np.asarray(edited.positions).reshape(-1, 3)[:, 2], 1.0, atol=1e-6)
    n = np.asarray(edited.normals).reshape(-1, 3)
    np.testing.assert_allclose(np.abs(n[:, 2]), 1, atol=1e-6)
    assert surface.fit_to_sensors([]) is None                  # levels given: nothing to fit


def test_an_edit_of_a_moved_restored_shape_keeps_its_translation(variant_llvm, tmp_path):
    """Through the plugin: the plane baked 0.02 above its low-poly, moved up by 1, raised by
    0.01 through mi.traverse, is at 1.03 (the edit used to drop the translation)."""
    bake(plane(z=0.02, n=8), plane(n=2), res=8, max_distance=0.05, pad=2, out_dir=tmp_path,
         map_formats=["d16"])
    scene = mi.load_dict({"type": "scene", "s": {
        "type": "restored", "map": str(tmp_path / "d16.png"), "levels": 2,
        "to_world": mi.ScalarTransform4f().translate([0, 0, 1])}})
    params = mi.traverse(scene)
    np.testing.assert_allclose(np.asarray(params["s.vertex_positions"])[2::3], 1.02, atol=1e-4)
    params["s.displacement"] = mi.TensorXf(np.array(params["s.displacement"]) + np.float32(0.01))
    params.update()
    z = np.asarray(params["s.vertex_positions"])[2::3]
    assert np.all(np.isfinite(z))
    np.testing.assert_allclose(z, 1.03, atol=1e-4)
