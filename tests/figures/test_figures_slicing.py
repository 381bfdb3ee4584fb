"""The donut table of `figures slicing` from a tradeoff result: failed points left out, bytes
and auto's slice count from the points' build_stats, the path curve appended."""
from mi_displace.evaluate import tradeoff as tr
from mi_displace.figures import slicing as figures


def _point(point, ok=True, **stats):
    row = {"point": {k: str(v) for k, v in point.items()}, "label": tr.point_label(point),
           "ok": ok}
    if ok:
        row.update(flip=0.1, build_s=0.2, render_warm_s=0.3, time_warm_s=0.5,
                   build_stats=[{"id": "floor"}, {"id": "donut", **stats}])
    return row


def test_donut_rows_from_a_sweep():
    methods = [("slicing a", {"direction": "a", "slices": 4}),
               ("slicing best auto", {"direction": "best", "slices": "auto"}),
               ("relief", {"mode": "relief", "relief_steps": 8}),
               ("vdm", {"mode": "vdm"})]
    result = {"points": [_point(methods[0][1], bytes=123),
                         _point(methods[1][1], bytes=456, slices=7),
                         _point(methods[2][1], ok=False),
                         _point(methods[3][1])],
              "path_curve": [{"spp": 1, "flip": 0.2, "render_s": 0.05, "time_s": 1.0}]}
    rows = figures.donut_rows(result, methods)
    assert [(r["method"], r["knob"], r["bytes"]) for r in rows] == [
        ("slicing a", 4, 123), ("slicing best auto", 7, 456), ("vdm", "default table", None),
        ("path", 1, None)]
    assert rows[0]["render_s"] == 0.3 and rows[-1]["render_s"] == 0.05
