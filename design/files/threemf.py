"""A 3MF file holding several meshes as separate objects (one per material, for a multi-nozzle slicer)."""
from __future__ import annotations

from pathlib import Path

import trimesh

from design.errors import DesignError


def write_objects(path: str | Path, objects: dict[str, trimesh.Trimesh]) -> None:
    """Write ``objects`` (name -> closed mesh, mm) as separate objects of one 3MF and check that it reads back.

    Each mesh keeps its own coordinates, so the objects sit where they are designed to (a slicer keeps
    their relative placement when it loads them as the parts of one print).

    Raises
    ------
    DesignError
        If the written file does not load back with one object of the same volume per name.
    """
    scene = trimesh.Scene()
    for name, mesh in objects.items():
        scene.add_geometry(mesh, node_name=name, geom_name=name)
    path = Path(path)
    scene.export(path, file_type="3mf")
    back = read_objects(path)
    for name, mesh in objects.items():
        got = back.get(name)
        if got is None or abs(got.volume - mesh.volume) > 1e-6 * max(abs(mesh.volume), 1.0):
            raise DesignError(f"{path}: object {name!r} does not read back from the 3MF as written")


def read_objects(path: str | Path) -> dict[str, trimesh.Trimesh]:
    """The named objects of a 3MF, each in its placed coordinates, mm."""
    loaded = trimesh.load(Path(path), file_type="3mf")
    if isinstance(loaded, trimesh.Trimesh):
        return {"object": loaded}
    return {name: loaded.geometry[geom].copy().apply_transform(loaded.graph[name][0])
            for name in loaded.graph.nodes_geometry for geom in [loaded.graph[name][1]]}
