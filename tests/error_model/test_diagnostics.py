"""Diagnostics: the text multivariate analysis and the PNG."""

from __future__ import annotations

from error_model.diagnostics import plot_diagnostics, summary_text


def test_summary_names_every_effect_with_its_interval(fitted_model):
    text = summary_text(fitted_model)
    assert "distance:" in text and "elevation:" in text
    assert "per 10 m" in text and "per 10 deg" in text
    assert "optional visible_fraction" in text and "not kept" in text
    assert "held-out coverage" in text
    assert "[" in text  # bootstrap interval shown


def test_plot_writes_a_png(fitted_model, train_table, tmp_path):
    path = plot_diagnostics(fitted_model, train_table, tmp_path / "diag.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 10_000
