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


def donut(direction):
    """A small brick donut (16 x 16 torus base, 8 slices) of the slicing plugin."""
    return {"type": "slicing", "base": "torus", "major_radius": 1.0, "minor_radius": 0.4,
            "resolution": 16, "scale": 0.08, "slices": 8, "direction": direction,
            "draw_base": True,
            "height": {"type": "bricks", "rows": 4, "columns": 2, "mortar": 0.12, "bevel": 0.2,
                       "to_uv": mi.ScalarTransform4f().scale([4, 2, 1])}}
