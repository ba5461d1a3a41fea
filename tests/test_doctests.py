"""The examples in the package's docstrings run and print what they say (numpydoc ``Example`` sections are
documentation a user copies, so they are tested like the README's code blocks)."""

from __future__ import annotations

import doctest
import importlib
import io
import pkgutil

import pytest

import mdsr_opt


def _modules_with_examples() -> list[str]:
    names = []
    finder = doctest.DocTestFinder(exclude_empty=True)
    for info in pkgutil.walk_packages(mdsr_opt.__path__, "mdsr_opt."):
        if info.name.endswith("__main__"):
            continue
        mod = importlib.import_module(info.name)
        if any(t.examples for t in finder.find(mod, info.name)):
            names.append(info.name)
    return sorted(names)


MODULES = _modules_with_examples()


def test_the_package_has_examples():
    assert len(MODULES) >= 30  # the examples are there to be tested (a broken finder would find none)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # examples that write files write them here
    mod = importlib.import_module(name)
    runner = doctest.DocTestRunner()
    out = io.StringIO()
    for test in doctest.DocTestFinder(exclude_empty=True).find(mod, name):
        runner.run(test, out=out.write)
    assert runner.failures == 0, out.getvalue()[-4000:]
