"""The part and what surrounds it: the mesh and its ray engine, built-in parts, the region
of interest, the table and fixtures, the collision world.
"""
