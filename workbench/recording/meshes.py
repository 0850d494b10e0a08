"""Meshes as rerun archetypes, for the recorders that log them on the timeline.

:meth:`workbench.recording.writer.Recorder.mesh` logs a mesh once, statically; a part that appears
or goes away during a run (a parachute at its deployment, a front shield until its release) is
logged at a time instead, with the archetype built here.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr

__all__ = ["mesh3d"]


def mesh3d(mesh: Any, albedo: Any) -> rr.Mesh3D:
    """A ``trimesh.Trimesh`` as a ``Mesh3D``: vertices [m] in the frame of the entity it is logged
    under (float32), triangles (uint32), vertex normals (float32) and one ``albedo`` factor
    (RGBA 0-255), so that a recorder can ``stream.log`` it at a set time."""
    return rr.Mesh3D(
        vertex_positions=mesh.vertices.astype(np.float32),
        triangle_indices=mesh.faces.astype(np.uint32),
        vertex_normals=mesh.vertex_normals.astype(np.float32),
        albedo_factor=albedo,
    )
