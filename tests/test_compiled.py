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
    from visloc.control import controller
    from visloc.flow import direct
    from visloc.markers import binarize, bits, contours, corners_batch, refine
    from visloc.model import rigid_body
    from visloc.pose import gauss_newton

    assert binarize._threshold is not None and contours.NATIVE_BORDERS and corners_batch.NATIVE_QUADS and refine.NATIVE_REFINE
    assert bits.NATIVE_CELLS and gauss_newton.NATIVE_LM and direct.NATIVE_DIRECT
    assert rigid_body._rigid is not None and controller._feedback is not None


SOURCES = {"_threshold": "visloc/markers/_threshold.c", "_borders": "visloc/markers/_borders.c", "_filter": "visloc/markers/_filter.c",
           "_quads": "visloc/markers/_quads.c", "_refine": "visloc/markers/_refine.c",
           "_cells": "visloc/markers/_cells.c", "_lm": "visloc/pose/_lm.c", "_direct": "visloc/flow/_direct.c",
           "_rigid": "visloc/model/_rigid.c", "_feedback": "visloc/control/_feedback.c"}


def _asan_runtime() -> str | None:
    cc = _compiler()
    if cc is None:
        return None
    import subprocess

    path = subprocess.run([cc, "-print-file-name=libasan.so"], check=False, capture_output=True, text=True).stdout.strip()
    return path if path and path != "libasan.so" and __import__("os").path.exists(path) else None


@pytest.mark.skipif(_asan_runtime() is None, reason="no C compiler with AddressSanitizer here")
def test_compiled_stages_under_address_and_undefined_behaviour_sanitizers(tmp_path):
    """Every compiled module, built with -fsanitize=address,undefined, through the detector,
    stage 8, the pose solver and the flow's direct stage on hostile but valid inputs (noise,
    one-pixel checkerboards, quads across the image border, huge motions): no memory error,
    no undefined behaviour (tests/_sanitized_workload.py)."""
    import os
    import subprocess
    import sys
    from concurrent.futures import ThreadPoolExecutor
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    include = sysconfig.get_paths()["include"]

    def build(item):  # -O0: nothing optimised away from the checks, and a third of -O1's build time
        name, src = item
        return subprocess.run([_compiler(), "-shared", "-fPIC", "-O0", "-g1", "-fsanitize=address,undefined",
                               "-fno-sanitize-recover=undefined", "-fno-omit-frame-pointer", f"-I{include}",
                               f"-I{root / 'visloc/markers'}", str(root / src), "-o", str(tmp_path / f"{name}.so")],
                              check=False, capture_output=True, text=True)

    with ThreadPoolExecutor(2) as pool:
        for result in pool.map(build, SOURCES.items()):
            assert result.returncode == 0, result.stderr
    env = dict(os.environ, LD_PRELOAD=_asan_runtime(), ASAN_OPTIONS="detect_leaks=0",
               UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1")
    run = subprocess.run([sys.executable, str(root / "tests/_sanitized_workload.py"), str(tmp_path)], env=env,
                         check=False, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and "fuzz ok" in run.stdout, run.stderr[-3000:]
