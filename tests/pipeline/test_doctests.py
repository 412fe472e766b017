"""Run the docstring examples of the pipeline modules this suite owns."""

import doctest
import importlib

import pytest

MODULES = ["pipeline.sphere_centres.sphere_fit", "pipeline.sphere_centres.line_of_sight_fit",
           "pipeline.sphere_centres.geometric_sphere_fit", "pipeline.chain.clustering",
           "pipeline.chain.gate", "pipeline.chain.ground", "pipeline.chain.quality",
           "pipeline.tables.marker_table", "pipeline.chain.stages", "pipeline.surveys.range_study"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name))
    assert result.failed == 0
