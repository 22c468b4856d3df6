"""The Examples sections of the docstrings run, and the public API has them (in the style of gpytoolbox, whose every
public function shows a few lines of use, and of scikit-fem, which runs its documented examples as tests)."""

import doctest
import importlib
import inspect
import pkgutil

import numpy as np
import pytest

import shspec

#: The packages whose ``__all__`` is the public API of the reference pages.
PUBLIC = ("shspec", "shspec.inverse", "shspec.fitting", "shspec.mesh", "shspec.spectral", "shspec.embed",
          "shspec.gaunt")

#: The share of public functions and classes that must show an Examples section.
MIN_SHARE = 0.9


def _public_objects() -> dict:
    """``"package.name"`` -> object for every function and class in the public packages' ``__all__``."""
    out = {}
    for package in PUBLIC:
        module = importlib.import_module(package)
        for name in module.__all__:
            obj = getattr(module, name)
            if inspect.isfunction(obj) or inspect.isclass(obj) or callable(getattr(obj, "py_func", None)):
                out.setdefault(id(obj), (f"{package}.{name}", obj))
    return dict(out.values())


def _has_examples(obj) -> bool:
    return "Examples\n" in (inspect.getdoc(obj) or "")


def test_most_public_functions_and_classes_show_examples():
    objects = _public_objects()
    missing = sorted(name for name, obj in objects.items() if not _has_examples(obj))
    share = 1 - len(missing) / len(objects)
    assert share >= MIN_SHARE, f"{share:.0%} of {len(objects)} have Examples; missing: {missing}"


def _modules():
    return sorted(m.name for m in pkgutil.walk_packages(shspec.__path__, "shspec.")
                  if not m.name.endswith("__main__"))


@pytest.mark.parametrize("name", _modules())
def test_the_examples_of_each_module_run(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # examples that write files write them here
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    with np.printoptions(legacy="1.25"):  # numpy scalars print as plain numbers, as the examples show them
        for test in finder.find(module, name, globs={}):
            if test.examples and test.name.startswith(name):
                runner.run(test, clear_globs=True)
    assert runner.failures == 0, f"{runner.failures} of {runner.tries} examples in {name} failed (output above)"
