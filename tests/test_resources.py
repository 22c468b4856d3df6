"""Memory and disk are estimated before a table or a forward solve allocates anything."""

import numpy as np
import pytest

import shspec.core.resources as resources
from shspec.errors import ResourceLimitError
from shspec.galerkin.model import HarmonicModel, forward_need
from shspec.gaunt.build import build_table
from shspec.gaunt.cache import get_table
from shspec.gaunt.table import plan_bytes, table_need, table_size


def test_estimates_are_the_real_sizes():
    table = build_table(14, 9)
    assert table_need(14, 9).memory == table.values.nbytes == 8 * table_size(14, 9)
    real_plan = sum(a.nbytes for a in table.plan.arrays[1:])
    assert real_plan <= plan_bytes(14, 9) <= 2.5 * real_plan
    n = (14 + 1) ** 2
    assert forward_need(14, 9).memory == table.values.nbytes + plan_bytes(14, 9) + 16 * n * n


def test_a_table_that_does_not_fit_is_refused_before_building(tmp_path, monkeypatch):
    import shspec.gaunt.cache as cache

    monkeypatch.setattr(resources, "available_memory", lambda: 2 * 2**20)
    monkeypatch.setattr(cache, "build_table", lambda *a, **k: pytest.fail("built although it does not fit"))
    with pytest.raises(ResourceLimitError, match=r"needs 12\.6 MiB of memory.*2\.0 MiB available.*Lb = \d+"):
        get_table(30, 30, cache_dir=tmp_path)
    assert not list(tmp_path.glob("*.h5"))


def test_disk_space_is_checked(tmp_path, monkeypatch):
    monkeypatch.setattr(resources, "free_disk", lambda path: 1000)
    with pytest.raises(ResourceLimitError, match="on disk"):
        get_table(12, 6, cache_dir=tmp_path)


def test_a_forward_solve_that_does_not_fit_names_what_fits(tmp_path, monkeypatch):
    monkeypatch.setattr(resources, "available_memory", lambda: 64 * 2**20)
    with pytest.raises(ResourceLimitError) as err:
        HarmonicModel(60, 30, cache_dir=tmp_path)
    lb, la = (int(x) for x in np.array(str(err.value).split("Lb = ")[-1].split(", La = ")))
    # the suggestion fits and one degree more would not
    assert forward_need(lb, la).memory <= 0.9 * 64 * 2**20
    assert forward_need(lb + 1, round((lb + 1) / 2)).memory > 0.9 * 64 * 2**20
    assert la == round(lb / 2)
