"""The validation report links only the figures its run wrote."""

import json
from pathlib import Path

from shspec.report import validation_markdown

EXAMPLES = Path(__file__).resolve().parents[1] / "docs" / "examples"


def test_a_report_links_the_caps_figure_only_when_there_are_caps():
    for name in ("blob", "bunny"):
        summary = json.loads((EXAMPLES / name / "summary.json").read_text())
        text = validation_markdown(summary)
        has_caps = bool(summary["ambiguity"] and summary["ambiguity"]["caps"])
        assert ("](ambiguity.png)" in text) == has_caps == (EXAMPLES / name / "ambiguity.png").exists()
        assert "![" in text and all((EXAMPLES / name / link.split(")")[0]).exists()
                                    for link in text.split("](")[1:] if link.split(")")[0].endswith(".png"))
