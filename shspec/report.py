"""The Markdown and HTML reports of shspec, in one place: an experiment's ``report.md``
(:func:`experiment_markdown`), a validation's ``report.md`` (:func:`validation_markdown`), and ``shspec report``,
which gathers experiment folders into one self-contained HTML page (:func:`build_report`).

Each folder written by :func:`shspec.experiments.run_experiment` holds ``meta.json``, ``config.json``,
``report.md``, CSV tables and PNG figures.  The page shows, per experiment, its finding, figures (linked relative to
the page, so the folder tree can be moved as a whole), tables, parameters and the versions that produced it.
"""

from __future__ import annotations

import csv
import html
import json
import os
from pathlib import Path

from .core.atomic import check_complete, write_text
from .errors import InvalidArgumentError

__all__ = ["build_report", "experiment_markdown", "validation_markdown", "markdown_table"]

_STYLE = """body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
h1{border-bottom:2px solid #444}h2{margin-top:2.2em;border-bottom:1px solid #bbb}
table{border-collapse:collapse;font-size:0.85em;margin:0.8em 0}td,th{border:1px solid #ccc;padding:2px 6px;
text-align:right}th{background:#f0f0f0}img{max-width:100%;border:1px solid #ddd;margin:0.5em 0}
.finding{background:#f6f8fa;padding:0.8em 1em;border-left:4px solid #4a7}pre{background:#f6f8fa;padding:0.6em;
font-size:0.8em;overflow-x:auto;white-space:pre}.meta{color:#666;font-size:0.85em}
.wide{max-width:100%;overflow-x:auto;margin:0.8em 0}.wide table{margin:0}th{position:sticky;top:0}
td,th{white-space:nowrap}"""


def _finding(report_md: str) -> str:
    part = report_md.split("## Finding", 1)[-1].strip()
    return part.split("\n\n", 1)[0].strip()


def _table(path: Path) -> str:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        return ""
    head = "".join(f"<th>{html.escape(c)}</th>" for c in rows[0])
    body = []
    for row in rows[1:]:
        cells = []
        for c in row:
            try:
                c = f"{float(c):.4g}"
            except ValueError:
                pass
            cells.append(f"<td>{html.escape(c)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    # a table wider than the page scrolls inside its own box instead of running past the page's edge
    return f'<div class="wide"><table><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table></div>'


def build_report(folders, out) -> Path:
    """Write an HTML page for the experiment ``folders`` to ``out`` (a .html path); returns its path.

    Raises
    ------
    InvalidArgumentError
        A folder is not an experiment run (no ``meta.json`` / ``report.md``).
    """
    out = Path(out)
    if out.suffix.lower() != ".html":
        raise InvalidArgumentError(f"the report must be an .html file, got {out}")
    runs = []
    for folder in folders:
        folder = Path(folder)
        candidates = [folder] if (folder / "meta.json").is_file() else sorted(
            p.parent for p in folder.glob("*/meta.json"))
        if not candidates:
            raise InvalidArgumentError(f"{folder} is not an experiment folder (no meta.json in it or below it)")
        runs.extend(candidates)
    out.parent.mkdir(parents=True, exist_ok=True)
    sections, toc = [], []
    for run in runs:
        check_complete(run)
        meta = json.loads((run / "meta.json").read_text())
        config = json.loads((run / "config.json").read_text()) if (run / "config.json").is_file() else {}
        finding = _finding((run / "report.md").read_text()) if (run / "report.md").is_file() else ""
        anchor = html.escape(run.name)
        toc.append(f'<li><a href="#{anchor}">{html.escape(meta["title"])}</a></li>')
        parts = [f'<h2 id="{anchor}">{html.escape(meta["title"])}</h2>',
                 f'<p class="meta">{html.escape(meta["reproduces"])}. Experiment <code>{html.escape(meta["experiment"])}'
                 f'</code>{" (quick)" if meta.get("quick") else ""}, {meta["seconds"]:.1f} s, shspec '
                 f'{html.escape(meta["shspec_version"])}, numpy {html.escape(meta["numpy"])}, Python '
                 f'{html.escape(meta["python"])}, {html.escape(meta["finished"])}.</p>',
                 f'<p class="finding">{html.escape(finding)}</p>']
        for png in sorted(run.glob("*.png")):
            rel = os.path.relpath(png, out.parent)
            parts.append(f'<img src="{html.escape(rel)}" alt="{html.escape(png.stem)}">')
        for table in sorted(run.glob("*.csv")):
            parts.append(f"<h3>{html.escape(table.stem)}</h3>{_table(table)}")
        parts.append(f"<h3>parameters</h3><pre>{html.escape(json.dumps(config, indent=1))}</pre>")
        sections.append("\n".join(parts))
    page = (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>shspec experiments</title>"
            f"<style>{_STYLE}</style></head><body><h1>shspec experiments</h1><ul>{''.join(toc)}</ul>\n"
            + "\n".join(sections) + "\n</body></html>\n")
    write_text(out, page)
    return out


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)


def markdown_table(rows: list[dict]) -> list[str]:
    """Lines of a Markdown table of rows (dicts with the keys of the first), floats to 3 significant digits."""
    if not rows:
        return []
    keys = list(rows[0])
    return (["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
            + ["| " + " | ".join(_fmt(r[k]) for k in keys) + " |" for r in rows])


def experiment_markdown(name: str, title: str, reproduces: str, quick: bool, seconds: float, version: str,
                        finding: str, figures, tables: dict, config: dict, cpu_seconds: float | None = None,
                        load: tuple | None = None) -> str:
    """The ``report.md`` of an experiment run: its finding, figures, tables and parameters.

    ``cpu_seconds`` (the process's CPU time) and ``load`` (the 1-minute load average before and after the run) are
    shown beside the wall time when given: on a shared machine the wall time alone says little."""
    timing = f"{seconds:.1f} s"
    if cpu_seconds is not None:
        timing += f" ({cpu_seconds:.1f} s CPU)"
    if load is not None and None not in load:
        timing += f", load {load[0][0]:.2f} before and {load[1][0]:.2f} after"
    lines = [f"# {title}", "", f"*Reproduces:* {reproduces}. *Run:* `shspec experiment {name}"
             f"{' --quick' if quick else ''}`, {timing}, shspec {version}.", "", "## Finding", "", finding, ""]
    for fig in figures:
        lines += [f"![{fig}]({fig})", ""]
    for table, rows in tables.items():
        if rows:
            lines += [f"## {table}", "", *markdown_table(rows), ""]
    lines += ["## Parameters", "", "```json", json.dumps(config, indent=1), "```", ""]
    return "\n".join(lines)


def _validation_fit_section(s: dict) -> str:
    """The plan and the fit of a validation, as a Markdown section ('' when neither ran)."""
    plan, fit = s.get("plan"), s.get("fit") or {}
    rows = []
    if plan is not None:
        rows += [("planned La / K / Lb", f"{plan['lmax_factor']} / {plan['numeig']} / {plan['lmax']}"),
                 ("predicted error of rho (floor of the basis, with the target's errors)",
                  f"{plan['predicted']:.3g} ({plan['floor']:.3g})")]
        if plan["diagnosis"]:
            rows.append(("diagnosis", plan["diagnosis"]))
    for key, label in (("factor_error", "fitted rho against the cMCF factors (relative L2, aligned)"),
                       ("floor", "floor: the best log expansion of degree La against them"),
                       ("log_correlation", "correlation of log rho with log c"),
                       ("error_bar", "error bar (the target's errors through the Jacobian)")):
        if fit.get(key) is not None:
            rows.append((label, f"{fit[key]:.3g}"))
    emb = s.get("fit_embedding")
    if emb is not None:
        rows.append(("re-embedded fit: Hausdorff / bounding-box diagonal", f"{emb['hausdorff_relative']:.3g}"))
    if not rows:
        return ""
    table = "\n".join(f"| {a} | {b} |" for a, b in rows)
    return f"\n## Hearing the shape: the log-rho fit of the target's spectrum\n\n| quantity | value |\n|---|---|\n{table}\n"


def validation_markdown(s: dict) -> str:
    """The ``report.md`` of :func:`shspec.pipeline.validate_target` from its summary (``summary.json``)."""
    rows = "\n".join(f"| {key} | {v:.3g} |" for key, v in s["spectral_error"].items())
    status = "\n".join(f"| {key} | {v} |" for key, v in s["status"].items())
    fe = s["factor_errors"]["embedded_vs_cmcf"]
    caps = ""
    if s["ambiguity"] is not None and not s["ambiguity"]["caps"]:
        caps = "\n## Bumps and dips\n\nNo caps (regions of positive Gaussian curvature) to test: nothing to mirror.\n"
    elif s["ambiguity"] is not None:
        caps = "\n".join(f"| {c['kind']} | {c['area_fraction']:.3f} | {c['rms_original']:.3g} | "
                         f"{c['rms_mirrored']:.3g} | {'yes' if c['ambiguous'] else 'no'} |" for c in s["ambiguity"]["caps"])
        caps = ("\n## Bumps and dips\n\nCaps (regions of positive Gaussian curvature) mirrored through the plane of "
                "their rim and relaxed; *ambiguous* means the edge lengths fit about as well either way, so the "
                "pressure prior (outwards) made the choice.\n\n| kind | area fraction | rms strain as embedded | "
                f"rms strain mirrored | ambiguous |\n|---|---|---|---|---|\n{caps}\n\n![caps](ambiguity.png)\n")
    fit = _validation_fit_section(s)
    text = f"""# Validation of `{s['name']}` ({s['nvertices']} vertices)

Generated by `shspec validate`. Numbers: `summary.json`.

## Re-embedding of the target's cMCF factors

| quantity | value |
|---|---|
| relative edge-length error (rms / max) | {s['edge_length_error']:.3g} / {s['edge_length_error_max']:.3g} |
| Hausdorff / bounding-box diagonal | {s['hausdorff_relative']:.3g} |
| Chamfer / bounding-box diagonal | {s['chamfer_relative']:.3g} |
| folded faces / self-intersections | {s['folded_faces']} / {s['self_intersections']} |
| continuation steps / Levenberg–Marquardt iterations | {s['embed_steps']} / {s['embed_iterations']} |
| time (s) | {s['embed_seconds']:.1f} |
| factor error of the re-embedded mesh (per-degree power, La = {s['lmax_factor']}) | {fe['power_error']:.3g} |
| factor error of the re-embedded mesh (L2 after Möbius + O(3) alignment) | {fe.get('aligned_l2_error')} |
| factor range of the target (min / max c) | {s['cmcf']['factor_min']:.3g} / {s['cmcf']['factor_max']:.3g} |

![meshes](meshes.png)

![factors](factors.png)

## Spectra (first {s['numeig']} eigenvalues)

Largest relative deviation from the target's PL spectrum, i ≥ 1:

| source | max_i \\|λ_i/λ_i(target) − 1\\| |
|---|---|
{rows}

![spectra](spectra.png)
{caps}{fit}
## Steps

| step | status |
|---|---|
{status}
"""
    return text
