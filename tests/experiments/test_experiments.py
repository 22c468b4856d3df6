"""Experiments run in --quick mode and write their folder; the HTML report is well formed and links only files."""

import csv
import json
import re
from html.parser import HTMLParser

import numpy as np
import pytest

from shspec.cli import main
from shspec.errors import InvalidArgumentError
from shspec.experiments import EXPERIMENTS, run_experiment
from shspec import HarmonicModel
from shspec.inverse import load_result_summary
from shspec.inverse.identifiability import identifiability
from shspec.report import build_report


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("experiments")
    for name in sorted(EXPERIMENTS):
        assert main(["experiment", name, "--quick", "--out", str(root / name)]) == 0
    return root


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(EXPERIMENTS))
def test_quick_run_writes_its_folder(runs, name):
    folder = runs / name
    for f in ("config.json", "meta.json", "report.md"):
        assert (folder / f).is_file()
    meta = json.loads((folder / "meta.json").read_text())
    assert meta["quick"] and meta["experiment"] == name
    # the run's CPU time and the load around it are recorded (Linux has a load average)
    assert 0 < meta["cpu_seconds"] and len(meta["load_average_start"]) == len(meta["load_average_end"]) == 3
    report = (folder / "report.md").read_text()
    finding = report.split("## Finding", 1)[1].strip().split("\n\n")[0]
    # a finding states its result with numbers (not boilerplate): several measured values appear in it
    assert len(re.findall(r"\d+(?:\.\d+)?(?:e[-+]?\d+)?", finding)) >= 3
    # every figure the report shows was written, and every table it has is a CSV beside it
    figures = re.findall(r"!\[[^]]*\]\(([^)]+)\)", report)
    assert figures and all((folder / f).is_file() for f in figures)
    for table in re.findall(r"^## (\S+)$", report, flags=re.M):
        if table not in ("Finding", "Parameters"):
            assert (folder / f"{table}.csv").is_file()


@pytest.mark.slow
def test_sh_convergence_finds_above_and_below(runs):
    numbers = json.loads((runs / "sh-convergence" / "meta.json").read_text())["numbers"]
    assert numbers["harmonic_from_above"] and numbers["pl_from_below"]
    assert 0.7 < numbers["pl_order_in_vertices"] < 1.3  # O(h^2) = O(1/V)


@pytest.mark.slow
def test_identifiability_reaches_full_rank_modulo_rotations(runs):
    numbers = json.loads((runs / "identifiability" / "meta.json").read_text())["numbers"]
    ranks = list(numbers["ranks"].values())
    assert ranks == sorted(ranks) and ranks[-1] == numbers["max_rank"]


@pytest.mark.slow
def test_identifiability_noisy_fits_follow_the_linear_prediction(runs):
    numbers = json.loads((runs / "identifiability" / "meta.json").read_text())["numbers"]
    assert all(0.5 < r < 2 for r in numbers["noisy_fit_ratio"])
    errors = numbers["noisy_fit_error"]
    assert errors == sorted(errors)


@pytest.mark.slow
def test_pl_perturbation_error_grows_with_p(runs):
    numbers = json.loads((runs / "pl-perturbation" / "meta.json").read_text())["numbers"]
    assert numbers["spearman_error_vs_p"] > 0.5
    assert (runs / "pl-perturbation" / "results.h5").is_file()


@pytest.mark.slow
def test_sh_inverse_reports_every_fit(runs):
    numbers = json.loads((runs / "sh-inverse" / "meta.json").read_text())["numbers"]
    config = json.loads((runs / "sh-inverse" / "config.json").read_text())
    model = HarmonicModel(config["lmax"], config["lmax_factor"])
    assert set(numbers) == {"raw", "regularized", "structured", "search"}
    for name, v in numbers.items():
        summary = load_result_summary(runs / "sh-inverse" / f"fit_{name}.h5")
        best = min(summary["starts"], key=lambda s: s.energy)
        assert v["energy"] == best.energy and v["iterations"] == best.iterations > 0
        # the spectral energy is recomputed from the best start's eigenvalues, without the regularizer
        target = summary["target"][:best.eigenvalues.size]
        relative = (best.eigenvalues - target) / np.where(target > 0, target, 1.0)
        expected = 0.5 * np.sum(relative[1:] ** 2)
        assert v["spectral_energy"] == pytest.approx(expected, rel=1e-12)
        # the error the residual implies, recomputed from the saved parameters and eigenvalues
        relative[0] = 0.0
        again = identifiability(model, best.params, target.size, residuals=relative)
        assert 0 < v["estimated_error"] == pytest.approx(again.estimated_error, rel=1e-6)
    # the default search (degree ramp, then a hop) ends far below the single-stage fit
    assert numbers["search"]["spectral_energy"] < 1e-3 * numbers["raw"]["spectral_energy"]
    assert numbers["raw"]["spectral_energy"] == pytest.approx(numbers["raw"]["energy"], rel=1e-12)


class _Checker(HTMLParser):
    VOID = {"meta", "img", "br", "hr", "link", "input"}

    def __init__(self):
        super().__init__()
        self.stack, self.links, self.errors = [], [], []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.links += [attrs[k] for k in ("src", "href") if k in attrs]
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack.pop() != tag:
            self.errors.append(tag)


@pytest.mark.slow
def test_report_is_well_formed_and_links_existing_files(runs, tmp_path):
    page = build_report([runs], tmp_path / "sub" / "report.html")
    checker = _Checker()
    checker.feed(page.read_text())
    assert not checker.errors and not checker.stack
    files = [x for x in checker.links if not x.startswith("#")]
    assert len(files) >= len(EXPERIMENTS)
    for link in files:
        assert (page.parent / link).resolve().is_file(), link


def test_config_override_and_errors(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text("numeig_values = [9, 16]\nrank_tol = 1e-6\n")
    run_experiment("identifiability", tmp_path / "run", config_path=cfg, quick=True, progress=False)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["numeig_values"] == [9, 16]
    assert (tmp_path / "run" / "config.toml").is_file()
    bad = tmp_path / "bad.toml"
    bad.write_text("no_such_key = 1\n")
    with pytest.raises(InvalidArgumentError, match="unknown keys"):
        run_experiment("identifiability", tmp_path / "x", config_path=bad, quick=True, progress=False)
    with pytest.raises(InvalidArgumentError, match="no experiment"):
        run_experiment("nope", tmp_path / "y")
    with pytest.raises(InvalidArgumentError, match="not an experiment folder"):
        build_report([tmp_path / "x"], tmp_path / "r.html")
    for name in ("pl-bunny", "pl-basin"):  # the shared meshes are looked for beside the checkout unless told
        missing = tmp_path / f"{name}.toml"
        missing.write_text(f"mesh_dir = '{tmp_path / 'no_meshes'}'\n")
        with pytest.raises(InvalidArgumentError, match="mesh_dir .* is not a directory"):
            run_experiment(name, tmp_path / name, config_path=missing, quick=True, progress=False)
    for text, match in (("perturbations = ['pink']", "'white' or 'smooth:L'"), ("sizes = [0.1, -1.0]", "positive")):
        bad = tmp_path / "basin.toml"
        bad.write_text(text + "\n")
        with pytest.raises(InvalidArgumentError, match=match):
            run_experiment("pl-basin", tmp_path / "basin", config_path=bad, quick=True, progress=False)


@pytest.mark.slow
def test_report_tables_scroll_instead_of_overflowing(runs, tmp_path):
    import re

    page = build_report([runs], tmp_path / "r.html").read_text()
    tables = page.count("<table>")
    assert tables > 0 and page.count('<div class="wide"><table>') == tables
    assert re.search(r"\.wide\{[^}]*overflow-x:auto", page)


@pytest.mark.slow
def test_pl_basin_converges_quadratically_next_to_the_truth(runs):
    with open(runs / "pl-basin" / "pl_basin.csv") as fh:
        rows = list(csv.DictReader(fh))
    near = min(rows, key=lambda r: float(r["start_log_rms"]))
    assert near["converged"] == "True" and float(near["relative_residual"]) <= 1e-10
    # a start 1e-4 from the truth comes back to within (1e-4)² times a curvature: 1.5e-8 measured
    assert float(near["log_rms_determined"]) < 1e-2 * float(near["start_log_rms"])
    numbers = json.loads((runs / "pl-basin" / "meta.json").read_text())["numbers"]
    assert numbers["per_numeig"]["60"]["determined_directions"] == 59  # K = 60 eigenvalues, λ₀ = 0 carries none
    with open(runs / "pl-basin" / "isospectral.csv") as fh:
        (walk,) = csv.DictReader(fh)
    # a step of 1e-2 along the null space, back to the spectrum: off the truth to second order (1.9e-4 measured)
    assert walk["converged"] == "True" and float(walk["relative_residual"]) <= 1e-12
    assert 1e-3 * 1e-2 ** 2 < float(walk["log_rms_determined"]) < 0.1 * 1e-2


@pytest.mark.slow
def test_sh_perturbation_sweeps_p_until_the_harmonic_basis_fails(runs):
    folder = runs / "sh-perturbation"
    config = json.loads((folder / "config.json").read_text())
    numbers = json.loads((folder / "meta.json").read_text())["numbers"]
    with open(folder / "sh_perturbation.csv") as fh:
        rows = list(csv.DictReader(fh))
    shapes = [f"Y_{l}^{m}" for l, m in config["shapes"]]
    assert list(dict.fromkeys(r["shape"] for r in rows)) == shapes == list(numbers)
    for shape in shapes:
        sweep = [r for r in rows if r["shape"] == shape]
        # in p order, ending at the first p the plan finds beyond the basis (the quick preset reaches one)
        assert [float(r["p"]) for r in sweep] == config["p_values"][:len(sweep)]
        assert [r["plan"] == "beyond basis" for r in sweep] == [False] * (len(sweep) - 1) + [True]
        assert numbers[shape]["beyond_basis_p"] == float(sweep[-1]["p"])
        for r in sweep:
            floor, predicted = float(r["floor"]), float(r["predicted"])
            assert 0 < floor <= predicted <= 1  # predicted = hypot(floor, the target's errors' bar)
            # the PL fit and the re-embeddings ran on every row, the last one too
            assert int(r["pl_numeig"]) == round(config["pl_numeig_fraction"] * int(r["vertices"]))
            assert 0 < float(r["pl_factor_error"]) < 1
            assert 0 < float(r["hausdorff_pl"]) < 0.5 and 0 < float(r["hausdorff_cmcf"]) < 0.5
        for r in sweep[:-1]:
            # fitted, and no closer to the cMCF factors than the best log expansion of the planned degree allows
            # (the alignment's Möbius map leaves a little slack)
            error, floor = float(r["factor_error"]), float(r["floor"])
            assert r["fit_status"] and not r["fit_status"].startswith("failed")
            assert 0.8 * floor <= error < 1 and 0 < float(r["hausdorff_fit"]) < 0.5
            assert float(r["error_bar"]) >= 0.99 * floor  # hypot(floor, the target's errors' bar)
        last = sweep[-1]
        assert last["fit_status"].startswith("not attempted") and last["factor_error"] == "nan"
        assert float(last["best_floor_analysed"]) > config["accuracy"]  # what "beyond the basis" means
        assert "cannot reach" in numbers[shape]["diagnosis"][-1]
    with open(folder / "sh_perturbation_fixed_degree.csv") as fh:
        fixed = list(csv.DictReader(fh))
    # the fit of the fixed degree ran where asked, from every eigenvalue, and finished (it crashed on an overflow once)
    assert [(r["shape"], float(r["p"])) for r in fixed] == [(s, p) for s in shapes for p in config["fixed_p"]]
    for r in fixed:
        assert int(r["lmax_factor"]) == config["fixed_degree"] and int(r["numeig"]) == config["numeig"]
        assert not r["fit_status"].startswith("failed")
        assert 0.8 * float(r["floor"]) <= float(r["factor_error"]) < 1


def test_sh_perturbation_refuses_a_sweep_it_cannot_end(tmp_path):
    for text, match in (("p_values = [1.0, 0.5]", "increasing"), ("shapes = [[3, 3, 1]]", r"\[l, m\] pairs")):
        bad = tmp_path / "sh.toml"
        bad.write_text(text + "\n")
        with pytest.raises(InvalidArgumentError, match=match):
            run_experiment("sh-perturbation", tmp_path / "sh", config_path=bad, quick=True, progress=False)
