"""Re-embedding time and accuracy for blob and bunny at ~1200, ~8000 and ~30000 vertices.

blob: icospheres (2562, 10242, 40962 vertices: the nearest sizes the shape offers).  bunny: bunny_1200.obj,
bunny.obj (8000) and bunny.obj subdivided once (31994 vertices, trimesh 4-to-1 subdivision).  For each: cMCF, then
:func:`shspec.embed.embed` of the cMCF factors (timed: wall and CPU time of this process; on a shared machine the
CPU time is the honest measure), the relative edge-length error, the edge error of the target
itself against the same lengths (the discretization level), folds, self-intersections and the Hausdorff/Chamfer
distance to the target over its bounding-box diagonal.  Writes benchmarks/results/bench_embed.json.

Run: python benchmarks/bench_embed.py [--quick] [--max-vertices N]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import trimesh

from shspec.embed import edge_length_error, embed, surface_distance
from shspec.mesh.cmcf import cmcf
from shspec.mesh.mesh_files import load_mesh
from shspec.mesh.shapes import blob
from shspec.mesh.triangle_mesh import TriangleMesh

MESHES = Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes"


def cases(quick: bool):
    yield "blob", lambda: blob(4)
    yield "bunny", lambda: load_mesh(MESHES / "bunny_1200.obj")
    if quick:
        return
    yield "blob", lambda: blob(5)
    yield "bunny", lambda: load_mesh(MESHES / "bunny.obj")

    def big_bunny():
        m = load_mesh(MESHES / "bunny.obj")
        v, f = trimesh.remesh.subdivide(m.vertices, m.faces)
        return TriangleMesh(v, f)

    yield "bunny", big_bunny
    yield "blob", lambda: blob(6)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only the smallest size")
    parser.add_argument("--max-vertices", type=int, default=None, help="skip larger meshes")
    parser.add_argument("--min-vertices", type=int, default=None, help="skip smaller meshes")
    args = parser.parse_args()
    rows = []
    for name, make in cases(args.quick):
        mesh = make()
        if ((args.max_vertices is not None and mesh.nvertices > args.max_vertices)
                or (args.min_vertices is not None and mesh.nvertices < args.min_vertices)):
            continue
        t = time.perf_counter()
        flow = cmcf(mesh)
        t_cmcf = time.perf_counter() - t
        res = embed(flow.sphere, flow.factors)
        level = edge_length_error(mesh, res.edges, res.target_lengths)[0]
        dist = surface_distance(res.mesh, mesh)
        row = {"shape": name, "nvertices": mesh.nvertices, "cmcf_seconds": t_cmcf, "embed_seconds": res.seconds,
               "embed_cpu_seconds": res.cpu_seconds, "continuation_retries": res.continuation_retries,
               "rejected_iterations": res.rejected_iterations,
               "steps": res.steps, "iterations": res.iterations, "cg_iterations": res.cg_iterations,
               "system_nnz": res.system_nnz, "edge_length_error": res.edge_error_rms,
               "edge_length_error_max": res.edge_error_max, "target_edge_length_error": level,
               "folded_faces": res.folded_faces, "self_intersections": res.self_intersections,
               "hausdorff_relative": dist.hausdorff_relative, "chamfer_relative": dist.chamfer_relative,
               "success": res.success, "factor_ratio": float(flow.factors.max() / flow.factors.min())}
        print(json.dumps(row), flush=True)
        rows.append(row)
    out = Path(__file__).resolve().parent / "results" / "bench_embed.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                                           "loadavg": os.getloadavg()},
                               "date": time.strftime("%Y-%m-%d %H:%M:%S"), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
