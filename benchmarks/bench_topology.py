"""How reliably the genus is read from a finite cotan spectrum: benchmarks/results/bench_topology.json.

Thirteen closed surfaces of genus 0-3 at two resolutions (coarse ≈ 1.2-2.6k vertices, fine ≈ 8-12k):

* genus 0: blob and an ellipsoid (icospheres moved), the shared bunny, spot (fine: one Loop subdivision of
  spot.obj) and blub;
* genus 1: tori of revolution with R/r = 1.5, 2 and 3;
* genus 2 and 3: chains of rings (:func:`shspec.mesh.implicit.ring_chain`), straight and bent.

For each surface the first 1000 eigenpairs (fewer on coarse meshes: at most n/2) are computed once and cached;
K = 100, 200, 500, 1000 use prefixes, and the noisy spectra λ_n(1 + εξ_n) (ε = 1e-4, 1e-3, ξ standard normal,
one seed per surface) are made from the same spectrum.  Each is read twice by
:func:`shspec.spectral.estimate_topology`: with the mesh's area known (the mesh path) and with the area fitted (the
spectrum alone); the noise level is passed on.  A surface counts as read correctly when the estimate is confident
and its genus is right; "confidently wrong" counts confident estimates with the wrong genus.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_topology.py [--cache DIR]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import load_average, machine_info, threads, write_json  # noqa: E402

from shspec.mesh.eigen import EigenOptions, mesh_spectrum  # noqa: E402
from shspec.mesh.implicit import euler_characteristic, ring_chain  # noqa: E402
from shspec.mesh.mesh_files import load_mesh  # noqa: E402
from shspec.mesh.shapes import blob, icosphere  # noqa: E402
from shspec.mesh.triangle_mesh import TriangleMesh  # noqa: E402
from shspec.mesh.validate import validate_mesh  # noqa: E402
from shspec.spectral import estimate_topology  # noqa: E402

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes"
KS = (100, 200, 500, 1000)
NOISES = (0.0, 1e-4, 1e-3)
RESOLUTIONS = ("coarse", "fine")
TARGET_VERTICES = {"coarse": 2500, "fine": 10000}


def _torus(ratio: float, vertices: int) -> TriangleMesh:
    minor = 1.0 / ratio
    n_minor = max(8, int(round(np.sqrt(vertices / ratio))))
    m = trimesh.creation.torus(1.0, minor, major_sections=int(round(vertices / n_minor)), minor_sections=n_minor)
    return TriangleMesh(m.vertices, m.faces)


def _chain(centers, minor: float, vertices: int) -> TriangleMesh:
    # Marching cubes gives about area / (0.82 spacing²) (measured) vertices; a ring's area is about 4π²·R·r.
    area = len(centers) * 4 * np.pi ** 2 * minor
    return ring_chain(centers, 1.0, minor, spacing=float(np.sqrt(area / (0.82 * vertices))))


def _ellipsoid(sub: int) -> TriangleMesh:
    ico = icosphere(sub)
    return TriangleMesh(ico.vertices * np.array([1.0, 0.8, 0.6]), ico.faces)


def _shared(name: str, resolution: str) -> TriangleMesh:
    if resolution == "coarse":
        return load_mesh(SHARED / f"{name}_1200.obj")
    mesh = load_mesh(SHARED / f"{name}.obj")
    if mesh.nvertices < 5000:
        v, f = trimesh.remesh.subdivide_loop(mesh.vertices, mesh.faces, iterations=1)
        mesh = TriangleMesh(v, f)
    return mesh


def surfaces():
    """name -> (genus, builder(resolution) -> TriangleMesh)."""
    sub = {"coarse": 4, "fine": 5}
    out = {
        "blob": (0, lambda r: blob(sub[r])),
        "ellipsoid": (0, lambda r: _ellipsoid(sub[r])),
        "torus-1.5": (1, lambda r: _torus(1.5, TARGET_VERTICES[r])),
        "torus-2": (1, lambda r: _torus(2.0, TARGET_VERTICES[r])),
        "torus-3": (1, lambda r: _torus(3.0, TARGET_VERTICES[r])),
        "chain-2": (2, lambda r: _chain([[0, 0], [2.2, 0]], 0.45, TARGET_VERTICES[r])),
        "chain-2-bent": (2, lambda r: _chain([[0, 0], [2.25, 0.5]], 0.5, TARGET_VERTICES[r])),
        "chain-3": (3, lambda r: _chain([[0, 0], [2.2, 0], [4.4, 0]], 0.45, TARGET_VERTICES[r])),
        "chain-3-L": (3, lambda r: _chain([[0, 0], [2.25, 0], [2.25, 2.25]], 0.5, TARGET_VERTICES[r])),
    }
    if SHARED.is_dir():
        for name in ("bunny", "spot", "blub"):
            out[name] = (0, lambda r, name=name: _shared(name, r))
    return out


def spectrum(name, resolution, build, cache: Path):
    path = cache / f"{name}-{resolution}.npz"
    if path.is_file():
        d = np.load(path)
        return d["eigenvalues"], float(d["area"]), int(d["nvertices"]), float(d["seconds"])
    mesh = validate_mesh(build(resolution), genus0=False)
    kmax = min(max(KS), mesh.nvertices // 2)
    t0 = time.perf_counter()
    # Up to n/2 pairs of a coarse mesh: a dense solve is faster than a Krylov basis of nearly n vectors.
    lam = mesh_spectrum(mesh, kmax, options=EigenOptions(dense_below=4000)).eigenvalues[:kmax].copy()
    seconds = time.perf_counter() - t0
    lam[0] = 0.0
    np.savez(path, eigenvalues=lam, area=mesh.area(), nvertices=mesh.nvertices, seconds=seconds,
             euler=euler_characteristic(mesh))
    return lam, mesh.area(), mesh.nvertices, seconds


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "shspec-bench-topology",
                        help="folder of cached spectra (reused between runs)")
    args = parser.parse_args(argv)
    args.cache.mkdir(parents=True, exist_ok=True)
    info = machine_info()
    shapes = surfaces()
    records, meshes = [], {}
    with threads(1):
        for name, (genus, build) in tqdm(shapes.items(), desc="surfaces"):
            for res in RESOLUTIONS:
                lam_all, area, nv, secs = spectrum(name, res, build, args.cache)
                meshes[f"{name}/{res}"] = {"genus": genus, "nvertices": nv, "area": area,
                                           "eigenpairs": int(lam_all.size), "eigensolve_s": round(secs, 2)}
                rng = np.random.default_rng([2026, sum(map(ord, name)), len(res)])
                xi = rng.standard_normal(lam_all.size)
                for eps in NOISES:
                    lam_noisy = np.sort(lam_all * (1.0 + eps * xi))
                    for k in KS:
                        if k > lam_all.size:
                            continue
                        for mode in ("area known", "area fitted"):
                            t0 = time.perf_counter()
                            est = estimate_topology(lam_noisy[:k], area if mode == "area known" else None,
                                                    relative_noise=eps)
                            records.append({
                                "surface": name, "resolution": res, "nvertices": nv, "true_genus": genus, "K": k,
                                "noise": eps, "mode": mode, "genus": est.genus, "confident": est.confident,
                                "correct": bool(est.confident and est.genus == genus),
                                "confidently_wrong": bool(est.confident and est.genus != genus),
                                "rounded_right": est.genus == genus,
                                "euler_characteristic": est.euler_characteristic,
                                "euler_characteristic_error": est.euler_characteristic_error,
                                "chi_error": est.euler_characteristic - (2 - 2 * genus),
                                "separation": est.separation, "area_relative_error": est.area / area - 1,
                                "model": [est.positive_powers, est.negative_powers], "window": list(est.window),
                                "estimate_s": round(time.perf_counter() - t0, 4)})
    summary = summarize(records, len(shapes))
    info["load_average_after"] = load_average()
    path = write_json("bench_topology.json", {"machine": info, "surfaces": meshes, "summary": summary,
                                              "records": records})
    print(markdown(summary))
    print(f"wrote {path}")
    return 0


def summarize(records, nsurfaces):
    table = []
    for mode in ("area known", "area fitted"):
        for res in RESOLUTIONS:
            for eps in NOISES:
                for k in KS:
                    sel = [r for r in records if r["mode"] == mode and r["resolution"] == res and r["noise"] == eps
                           and r["K"] == k]
                    if not sel:
                        continue
                    table.append({"mode": mode, "resolution": res, "noise": eps, "K": k, "surfaces": len(sel),
                                  "correct": sum(r["correct"] for r in sel),
                                  "confidently_wrong": sum(r["confidently_wrong"] for r in sel),
                                  "rounded_right": sum(r["rounded_right"] for r in sel),
                                  "median_abs_chi_error": float(np.median([abs(r["chi_error"]) for r in sel])),
                                  "median_chi_sigma": float(np.median([r["euler_characteristic_error"]
                                                                       for r in sel])),
                                  "max_abs_chi_error_confident": max([abs(r["chi_error"]) for r in sel
                                                                      if r["confident"]], default=None)})
    area = []
    for res in RESOLUTIONS:
        for k in KS:
            sel = [abs(r["area_relative_error"]) for r in records if r["mode"] == "area fitted"
                   and r["resolution"] == res and r["noise"] == 0.0 and r["K"] == k]
            if sel:
                area.append({"resolution": res, "K": k, "surfaces": len(sel), "median": float(np.median(sel)),
                             "max": float(max(sel)), "within_1_percent": int(sum(e < 0.01 for e in sel))})
    wrong = sum(r["confidently_wrong"] for r in records)
    return {"surfaces": nsurfaces, "table": table, "area_from_spectrum": area, "confidently_wrong_total": wrong,
            "estimates": len(records)}


def markdown(summary) -> str:
    lines = []
    for mode in ("area known", "area fitted"):
        lines += [f"\n{mode}: surfaces read correctly (confident and right) / surfaces", "",
                  "| resolution | noise | " + " | ".join(f"K = {k}" for k in KS) + " |",
                  "|---|---|" + "---|" * len(KS)]
        for res in RESOLUTIONS:
            for eps in NOISES:
                cells = []
                for k in KS:
                    row = [r for r in summary["table"] if r["mode"] == mode and r["resolution"] == res
                           and r["noise"] == eps and r["K"] == k]
                    if row:
                        r = row[0]
                        bad = f" ({r['confidently_wrong']} wrong)" if r["confidently_wrong"] else ""
                        cells.append(f"{r['correct']}/{r['surfaces']}{bad}")
                    else:
                        cells.append("–")
                lines.append(f"| {res} | {eps:g} | " + " | ".join(cells) + " |")
    lines += ["", "area from the spectrum alone (noise 0): median / max relative error", "",
              "| resolution | " + " | ".join(f"K = {k}" for k in KS) + " |", "|---|" + "---|" * len(KS)]
    for res in RESOLUTIONS:
        cells = []
        for k in KS:
            row = [r for r in summary["area_from_spectrum"] if r["resolution"] == res and r["K"] == k]
            cells.append(f"{row[0]['median']:.1e} / {row[0]['max']:.1e}" if row else "–")
        lines.append(f"| {res} | " + " | ".join(cells) + " |")
    lines.append(f"\nconfidently wrong, all {summary['estimates']} estimates: {summary['confidently_wrong_total']}")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
