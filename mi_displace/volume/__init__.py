"""Discontinuous displacement mapping for volume graphics (Correa, Silver, Chen 2006).

objects (O_j and ∇O_j), maps (procedural inverse displacements D, α), displacement (D_k
textures, placement M, composition), field (the displaced object, majorant, normals),
slicing (the §4.2 renderer), isosurface (the surface reference), animation, cli.
"""
