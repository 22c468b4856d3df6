"""``shspec experiment`` and ``shspec report``: the study's experiments, one command each, and their report."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..experiments import EXPERIMENTS, run_experiment
from ..report import build_report


def register(sub) -> None:
    listing = "\n".join(f"  {e.name:16s} {e.title} (full run about {e.expected_minutes:g} min)"
                        for e in sorted(EXPERIMENTS.values(), key=lambda e: e.name))
    p = sub.add_parser(
        "experiment", help="run one of the study's experiments into a folder with a report",
        description="Run an experiment and write a folder with config.json (and your TOML), raw results (CSV), "
        "figures (PNG), meta.json and report.md stating the finding with its numbers.",
        epilog="experiments:\n" + listing + "\n\nA --config TOML file overrides the defaults by key (the keys are "
        "listed in each run's config.json).", formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("name", choices=sorted(EXPERIMENTS), metavar="NAME", help="experiment to run (see below)")
    p.add_argument("--config", help="TOML file with parameters overriding the defaults")
    p.add_argument("--quick", action="store_true", help="a reduced version that runs in under a minute")
    p.add_argument("--out", help="output folder (default: experiments/NAME)")
    p.set_defaults(func=_run)

    r = sub.add_parser("report", help="gather experiment folders into one HTML page",
                       description="Collect the experiment folders (or folders containing them) into one HTML page "
                       "with figures inline, tables, parameters and versions.")
    r.add_argument("folders", nargs="+", help="experiment folders, or folders holding several")
    r.add_argument("--out", default="report.html", help="the HTML file to write (default report.html)")
    r.set_defaults(func=_report)


def _run(args) -> int:

    run_experiment(args.name, Path(args.out or Path("experiments") / args.name), config_path=args.config,
                   quick=args.quick)
    return 0


def _report(args) -> int:

    path = build_report(args.folders, args.out)
    print(f"wrote {path}")
    return 0
