"""Assets the scenes and the runtime read (meshes, teapot patches, textures, volumes), each
folder with its LICENSE.txt: package data (see :mod:`mi_displace.core.resources`)."""
