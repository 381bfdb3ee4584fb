"""VDM: view-dependent displacement mapping (paper 001)."""

#: The smallest VDM set-up, a ``vdm_mesh`` with its ``vdm`` BSDF, as an XML fragment: the
#: examples of both plugins in the plugin reference (``docs/plugins.md``).
EXAMPLE_XML = """<shape type="vdm_mesh">
    <string name="base" value="torus"/>
    <integer name="resolution" value="16"/>
    <bsdf type="vdm">
        <texture type="cells" name="height"/>
        <float name="depth" value="0.03"/>
        <integer name="res" value="16"/>
        <integer name="theta" value="4"/>
        <integer name="phi" value="8"/>
        <integer name="curvatures" value="2"/>
        <bsdf type="diffuse"/>
    </bsdf>
</shape>"""
