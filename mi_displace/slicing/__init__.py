"""Displacement mapping by slicing the displacement volume, image-based depth objects and
visual hulls (Kautz & Seidel 2001, paper 002).

* :mod:`geometry` — the base polygons, the slice polygons a GPU would draw (surface-aligned
  §3.1, orthogonal §3.2), the displacement volume's boundary, slice counts (§3.4);
* :mod:`trace` — the front-to-back slice loops (first slice passing the α-test wins);
* :mod:`depth_object` — six orthographic colour+depth images on a cube (§4), visual hull (§5).

The paper's algorithm as real OpenGL (the benchmark's peer) is in the lab, not here:
:class:`mi_displace.bench.peers.llvmpipe.GLSlices`.
"""
