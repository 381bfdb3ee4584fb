"""Discontinuous displacement mapping for volume graphics (Correa, Silver, Chen 2006).

objects (O_j and ∇O_j), maps (procedural inverse displacements D, α), displacement (D_k
textures, placement M, composition), field (the displaced object, majorant, normals),
slicer (the §4.2 renderer), isosurface (the surface reference), animation, cli.
"""

#: The smallest displaced volume with a map, as an XML fragment (id ``volume``): the
#: examples of the plugin reference use it (``docs/plugins.md``).
EXAMPLE_XML = """<volume type="displaced_volume" id="volume">
    <string name="procedural" value="piggy_bank"/>
    <integer name="resolution" value="24"/>
    <string name="mode" value="approximation"/>
    <string name="map0_type" value="peel"/>
    <float name="map0_angle" value="45"/>
    <integer name="map0_resolution" value="16"/>
</volume>"""
