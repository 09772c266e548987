"""Fixtures for the model tests: the report's tables as transcribed in datasets/ardrone2/."""

import csv
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[2] / "datasets" / "ardrone2"


def _read(name: str) -> list[dict[str, str]]:
    with open(DATA / name, newline="") as fh:
        lines = [line for line in fh if not line.startswith("#")]
    return list(csv.DictReader(lines))


@pytest.fixture
def table():
    """``table("file.csv")`` -> list of rows (dicts of the printed strings), comments skipped."""
    return _read


def decimals(text: str) -> int:
    """Number of decimals a printed number carries ("0.0071" -> 4, "0.1387e-3" -> 7)."""
    mantissa, _, exponent = text.lower().partition("e")
    places = len(mantissa.partition(".")[2])
    return places - int(exponent or 0)


@pytest.fixture
def printed_decimals():
    return decimals


def pytest_generate_tests(metafunc):
    """Parametrize ``bifilar_row`` over every row of the report's Appendix D tables."""
    if "bifilar_row" in metafunc.fixturenames:
        rows = _read("appendix_d_bifilar.csv")
        metafunc.parametrize("bifilar_row", rows, ids=[f"line{r['line']}" for r in rows])
