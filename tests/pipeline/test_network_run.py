"""Marker tables in, adjusted network out (:func:`pipeline.network.run.adjust_tables`)."""

import numpy as np
import pytest

from error_model import default_model
from markerplan.errors import ConfigError
from pipeline.network import detections
from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.observations import Datum
from pipeline.network.run import adjust_tables
from tests.cli.network_inputs import write_network_inputs


@pytest.fixture(scope="module")
def network(tmp_path_factory):
    return write_network_inputs(tmp_path_factory.mktemp("network"), n_stations=4, seed=3)


def test_read_identify_adjust_in_one_call(network):
    model, settings = default_model(), AdjustmentSettings()
    asked = []

    def reference(stations):
        asked.append([s.station_id for s in stations])
        return "S02"

    run = adjust_tables(network.tables, model, reference, detections.identify_from_table,
                        settings)
    stations = detections.read_detections(list(network.tables), model)
    obs = detections.network_observations(detections.identify_from_table(stations))
    expected = adjust(obs, Datum("station", "S02"), settings)
    assert asked == [list(network.station_ids)]
    assert run.reference_station == "S02"
    assert run.observations.station_ids == obs.station_ids
    np.testing.assert_array_equal(run.result.pose, expected.pose)
    np.testing.assert_array_equal(run.result.marker_xyz_m, expected.marker_xyz_m)
    assert set(run.timings_s) == {"read", "identify", "adjust"}


def test_the_reference_choice_may_refuse(network):
    def reference(stations):
        raise ConfigError("no station S9 in the marker tables")

    with pytest.raises(ConfigError, match="S9"):
        adjust_tables(network.tables, default_model(), reference,
                      detections.identify_from_table, AdjustmentSettings())
