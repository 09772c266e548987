"""``visloc info``: what a source holds, before a run: a recording's topics (type, count,
rate), a video's frames, rate and size, an image folder's count and size."""

from __future__ import annotations

import argparse
import json
import os

from visloc.errors import UsageError


def _describe(source: str) -> dict:
    """The facts ``visloc info`` prints, as a dict."""
    from visloc.io import open_source
    from visloc.io.bags import is_recording, recording_topics

    if is_recording(source):
        return {"source": source, "kind": "recording", "topics": recording_topics(source)}
    if source.strip().isdigit():
        raise UsageError("info describes files and folders, not cameras")
    with open_source(source) as src:
        kind = {"ImageListSource": "images", "VideoSource": "video"}.get(type(src).__name__, type(src).__name__)
        out: dict = {"source": source, "kind": kind}
        try:
            out["frames"] = len(src)
        except TypeError:
            out["frames"] = None
        for attr in ("native_fps", "frame_count"):
            if getattr(src, attr, None) is not None:
                out[attr] = getattr(src, attr)
        first = next((f for f in src if f.image is not None), None)
        out["size"] = None if first is None else [int(first.image.shape[1]), int(first.image.shape[0])]
        out["readable"] = first is not None  # False: not one frame decodes
    return out


def info(args: argparse.Namespace) -> int:
    """``visloc info``: print what ``args.source`` holds (a table, or JSON with ``--json``).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc info`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status 0; 1 when a folder or video holds no frame that can be read (``readable``
        false in the JSON).
    """
    facts = _describe(os.fspath(args.source))
    if args.json:
        print(json.dumps(facts, indent=1))
        return 0 if facts.get("readable", True) else 1
    print(f"{facts['source']}: {facts['kind']}")
    if facts["kind"] == "recording":
        print(f"  {'topic':<32} {'type':<36} {'count':>7} {'rate Hz':>8}")
        for t in facts["topics"]:
            rate = "-" if t["rate_hz"] is None else f"{t['rate_hz']:.2f}"
            print(f"  {t['topic']:<32} {t['type']:<36} {t['count']:>7} {rate:>8}")
    else:
        size = "no frame can be read" if facts["size"] is None else f"{facts['size'][0]} x {facts['size'][1]} px"
        frames = "unknown" if facts["frames"] is None else facts["frames"]
        rate = f", {facts['native_fps']:g} fps" if "native_fps" in facts else ""
        print(f"  {frames} frames{rate}, {size}")
    return 0 if facts.get("readable", True) else 1
