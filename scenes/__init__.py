"""Example and comparison scenes, their include files and parts: package data (see
:mod:`mi_displace.core.resources`)."""
