"""Run the docstring examples of the pipeline modules this suite owns."""

import doctest
import importlib

import pytest

MODULES = ["pipeline.sphere_fit", "pipeline.line_of_sight_fit", "pipeline.geometric_sphere_fit",
           "pipeline.clustering", "pipeline.gate", "pipeline.ground", "pipeline.quality",
           "pipeline.marker_table", "pipeline.stages", "pipeline.range_study"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name))
    assert result.failed == 0
