"""Sensor profiles: everything the simulator needs to know about the rig's errors, in one file.

A profile names the VLP-16's range noise and beam footprint (:class:`~visibility.sensor.
SensorConfig`), the turntable's per-frame errors (:class:`~visibility.sensor.TurntableErrors`)
and the error of the reference a field experiment is evaluated against
(:class:`~visibility.total_station.TotalStationReference`), plus, for a calibrated profile, how
its free parameters were fitted (``calibration``: the data, the fitted values with their
uncertainty, the command). ``simulate``, ``range-study``, ``verify`` and
``scripts/make_default_error_model.py`` take ``--sensor-profile NAME|FILE``.

Two profiles ship in ``visibility/data/sensor_profiles/``:

``calibrated`` (the default)
    The datasheet's physics with its free parameters fitted by ``markerplan calibrate-sensor``
    to the published field experiment's per-position edge residuals.
``datasheet``
    Velodyne's figures only: +-3 cm range accuracy read as 2 sigma, 2 mm resolution, the
    3 x 1.5 mrad footprint; a perfect turntable and a perfect reference.

File format (JSON): ``format`` = ``"markerplan-sensor-profile"``, ``format_version`` = 1,
``name``, ``description``, ``sensor`` {fields of SensorConfig except ``rpm``}, ``turntable``
{fields of TurntableErrors}, ``reference`` {fields of TotalStationReference}, ``calibration``
(object or null) and ``provenance``. Missing fields take the datasheet values; unknown ones are
refused by name.
"""

from __future__ import annotations

import functools
import json
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

from markerplan.errors import ConfigError, InputFileError
from markerplan.reading import check_schema_version, load_json, require_type
from visibility.sensor import RigConfig, SensorConfig, TurntableErrors
from visibility.total_station import TotalStationReference

FORMAT = "markerplan-sensor-profile"
FORMAT_VERSION = 1
PROFILE_DIR = Path(__file__).resolve().parent / "data" / "sensor_profiles"
BUILTIN_PROFILES = ("calibrated", "datasheet")
DEFAULT_PROFILE = "calibrated"


@dataclass(frozen=True)
class SensorProfile:
    """A named set of sensor, turntable and reference errors.

    Attributes
    ----------
    name : str
    description : str
    sensor : SensorConfig
        ``rpm`` is the command's choice (``--rpm``), not part of the profile.
    turntable : TurntableErrors
    reference : TotalStationReference
    calibration : dict or None
        How the profile was fitted (see :mod:`planner.studies.sensor_calibration`).
    """

    name: str
    description: str = ""
    sensor: SensorConfig = SensorConfig(beam_divergence=True)
    turntable: TurntableErrors = TurntableErrors()
    reference: TotalStationReference = TotalStationReference()
    calibration: dict | None = None

    def with_values(self, values: dict[str, float]) -> SensorProfile:
        """A copy with parameters replaced, named ``block.field`` (e.g. ``sensor.range_noise_m``).

        Examples
        --------
        >>> p = SensorProfile("x").with_values({"turntable.encoder_noise_rad": 1e-4})
        >>> p.turntable.encoder_noise_rad
        0.0001
        """
        blocks: dict[str, dict[str, Any]] = {}
        for key, value in values.items():
            block, name = _split(key)
            blocks.setdefault(block, {})[name] = value
        return replace(self, **{b: replace(getattr(self, b), **v) for b, v in blocks.items()})

    def sensor_config(self, rpm: int = 600, **overrides) -> SensorConfig:
        """This profile's :class:`SensorConfig` at ``rpm``, with the ``overrides`` that are not
        ``None`` (a command's explicit options, e.g. ``range_noise_m=0.01``) replacing its
        fields.

        Examples
        --------
        >>> s = SensorProfile("x").sensor_config(300, range_noise_m=0.01, dropout_prob=None)
        >>> s.rpm, s.range_noise_m, s.dropout_prob, s.beam_divergence
        (300, 0.01, 0.0, True)
        """
        given = {k: v for k, v in overrides.items() if v is not None}
        return replace(self.sensor, rpm=rpm, **given)

    def rig_config(self, **settings) -> RigConfig:
        """A :class:`RigConfig` with this profile's turntable errors and the given ``settings``
        (``lidar_height_m``, ``frames_per_turn``, ``offsets``)."""
        return RigConfig(turntable=self.turntable, **settings)

    def value(self, key: str) -> float:
        """The parameter named ``block.field``."""
        block, name = _split(key)
        return getattr(getattr(self, block), name)

    def to_dict(self) -> dict:
        """The JSON document of this profile (``provenance`` added by :func:`save_profile`)."""
        sensor = asdict(self.sensor)
        sensor.pop("rpm")
        return {"format": FORMAT, "format_version": FORMAT_VERSION, "name": self.name,
                "description": self.description, "sensor": sensor,
                "turntable": asdict(self.turntable), "reference": asdict(self.reference),
                "calibration": self.calibration}


_BLOCKS = {"sensor": SensorConfig, "turntable": TurntableErrors,
           "reference": TotalStationReference}


def _field_names(block: str) -> list[str]:
    return [f.name for f in fields(_BLOCKS[block]) if f.name != "rpm"]


def _split(key: str) -> tuple[str, str]:
    """``block.field`` -> (block, field), refusing names a profile does not have."""
    block, _, name = key.partition(".")
    if block not in _BLOCKS or name not in _field_names(block):
        raise ConfigError(f"unknown sensor-profile parameter {key!r}; parameters are "
                          f"{', '.join(parameter_names())}")
    return block, name


def parameter_names() -> list[str]:
    """Every ``block.field`` name a profile has (``rpm`` excluded)."""
    return [f"{b}.{n}" for b in _BLOCKS for n in _field_names(b)]


def load_profile(name_or_path: str | Path) -> SensorProfile:
    """A shipped profile by name (``calibrated``, ``datasheet``) or a profile JSON file.

    Raises
    ------
    InputFileError
        Unreadable file, wrong format, unknown field, or a value out of range (one line).
    """
    text = str(name_or_path)
    if text in BUILTIN_PROFILES:
        path = PROFILE_DIR / f"{text}.json"
    else:
        path = Path(text)
        if not path.exists():
            raise InputFileError(f"sensor profile {text!r} is neither a shipped profile "
                                 f"({', '.join(BUILTIN_PROFILES)}) nor an existing file; give "
                                 "one of those names or a JSON file from calibrate-sensor")
    what = f"sensor profile {path}"
    doc = load_json(path, what)
    if doc.get("format") != FORMAT:
        raise InputFileError(f"{what}: not a sensor profile (format {doc.get('format')!r}, "
                             f"expected {FORMAT!r}); write one with markerplan calibrate-sensor")
    check_schema_version(doc.get("format_version"), FORMAT_VERSION, what)
    blocks = {}
    datasheet = SensorProfile("")  # missing fields take its values
    for block in _BLOCKS:
        values = require_type(doc.get(block, {}), dict, f"{what}: {block}")
        unknown = sorted(set(values) - set(_field_names(block)))
        if unknown:
            raise InputFileError(f"{what}: {block} has no field {unknown[0]!r}; its fields are "
                                 f"{', '.join(_field_names(block))}")
        try:
            blocks[block] = replace(getattr(datasheet, block), **values)
        except (ConfigError, TypeError) as exc:
            raise InputFileError(f"{what}: {exc}") from None
    calibration = doc.get("calibration")
    if calibration is not None:
        require_type(calibration, dict, f"{what}: calibration")
    return SensorProfile(str(require_type(doc.get("name", path.stem), str, f"{what}: name")),
                         str(doc.get("description", "")), calibration=calibration, **blocks)


@functools.cache
def default_profile() -> SensorProfile:
    """The shipped :data:`DEFAULT_PROFILE` (read once per process)."""
    return load_profile(DEFAULT_PROFILE)


def save_profile(profile: SensorProfile, path: str | Path, provenance: dict) -> Path:
    """Write ``profile`` as JSON (sorted keys, byte-identical for the same profile)."""
    path = Path(path)
    body = {**profile.to_dict(), "provenance": provenance}
    path.write_text(json.dumps(body, indent=1, sort_keys=True) + "\n")
    return path
