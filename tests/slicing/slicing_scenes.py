"""Scene pieces shared by the slicing tests, imported by name (a helper module, not
``conftest``: ``from conftest import`` resolves to whichever conftest pytest imported last when
it is given files from several folders)."""
import mitsuba as mi

MATERIAL = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.5, 0.4]}}


def bricks_torus(**kw):
    """Common keywords of a bricks torus (``slicing`` or ``displaced``; add ``type``)."""
    bricks = {"type": "bricks", "rows": 4, "columns": 2, "mortar": 0.15, "bevel": 0.2,
              "to_uv": mi.ScalarTransform4f().scale([4, 2, 1])}
    return {"base": "torus", "major_radius": 1.0, "minor_radius": 0.4, "scale": 0.1,
            "height": bricks, "bsdf": MATERIAL, **kw}
