"""Choosing between the compiled stages and their Python versions."""

import shutil
import sysconfig
import types

import pytest

from visloc._compiled import use_compiled


def test_use_compiled_follows_the_request_and_what_was_built():
    built = types.ModuleType("_stage")
    assert use_compiled(None, built, "visloc.markers._stage") is True
    assert use_compiled(None, None, "visloc.markers._stage") is False
    assert use_compiled(False, built, "visloc.markers._stage") is False
    assert use_compiled(True, built, "visloc.markers._stage") is True
    with pytest.raises(RuntimeError, match=r"visloc\.markers\._stage was not built"):
        use_compiled(True, None, "visloc.markers._stage")


def _compiler() -> str | None:
    cc = (sysconfig.get_config_var("CC") or "").split()
    return shutil.which(cc[0]) if cc else None


@pytest.mark.skipif(_compiler() is None, reason="no C compiler here: the Python versions run")
def test_every_stage_was_compiled_where_a_compiler_is():
    """With a compiler at install the C code must have been built: a broken build would
    otherwise fall back silently and only the bench would notice."""
    from visloc.markers import contours, corners_batch, refine
    from visloc.pose import gauss_newton

    assert contours.NATIVE_BORDERS and corners_batch.NATIVE_QUADS and refine.NATIVE_REFINE
    assert gauss_newton.NATIVE_LM
