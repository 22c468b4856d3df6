"""The README's mesh section, executed: this snippet must stay identical to the one in README.md."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
MESHES = REPO.parent / "shared" / "data" / "meshes"

SNIPPET = '''
import matplotlib
matplotlib.use("Agg")
from shspec.mesh import load_mesh, cmcf, plot_hammer, mesh_spectrum

bunny = load_mesh("../shared/data/meshes/bunny.obj")       # validated: closed, manifold, genus 0
result = cmcf(bunny)                                         # conformal map to the unit sphere
print(f"roundness {result.roundness:.1e} after {result.iterations} steps, {result.flips} flips")
fig = plot_hammer(result.sphere, result.factors, log=True, label="conformal factor")
fig.savefig("bunny_factors.png")
spec = mesh_spectrum(bunny, 10)                              # cotan eigenvalues, 1/(mesh unit)^2
print(spec.eigenvalues.round(1))
'''


@pytest.mark.skipif(not MESHES.is_dir(), reason=f"test meshes not found at {MESHES}")
def test_readme_mesh_snippet(tmp_path, monkeypatch):
    # The snippet's paths are relative to the repository root; the figure goes to a scratch directory.
    monkeypatch.chdir(REPO)
    code = SNIPPET.replace('"bunny_factors.png"', repr(str(tmp_path / "bunny_factors.png")))
    exec(compile(code, "README.md", "exec"), {})
    assert (tmp_path / "bunny_factors.png").stat().st_size > 10_000
