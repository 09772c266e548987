"""Real photographs: visloc vs OpenCV ArUco vs AprilTag 3 on every labelled real image, plus marker-free photos.

Images: ``datasets/real/manifest.json`` (OpenCV's ArUco tutorial photos, AprilTag's NASA
Swarmathon test photos) and ``datasets/real/field/manifest.json`` (robot-camera photos from
UbiquityRobotics/fiducials, AprilTags.jl, zoloto, sb-vision). Marker-free photos: the natural
images of scikit-image's data set, tried with nine dictionaries (any detection is a false positive).

Methods, each on the grey image (``cv2.IMREAD_GRAYSCALE``), the peers configured as their docs
recommend (``bench/_peers.py``):

- ``visloc``: ``visloc.markers.MarkerDetector(dictionary).detect(gray)`` with its defaults.
- ``opencv``: ``cv2.aruco.ArucoDetector(dictionary, cv2.aruco.DetectorParameters())``, i.e. OpenCV's
  defaults (adaptive threshold windows 3..23 step 10, constant 7, corner refinement NONE).
- ``opencv_subpix``: the same with ``cornerRefinementMethod = CORNER_REFINE_SUBPIX`` (default
  window 5, 30 iterations, min accuracy 0.1).
- ``apriltag3``: ``pupil_apriltags.Detector(families=F, nthreads=1, quad_decimate=1.0,
  quad_sigma=0.0, refine_edges=True, decode_sharpening=0.25)`` for the AprilTag dictionaries only
  (``DICT_APRILTAG_16h5/25h9/36h11`` -> ``tag16h5/25h9/36h11``); corners converted to OpenCV order
  and pixel-centre convention with ``corners[[1, 0, 3, 2]] - 0.5``. It runs in a child process
  (``_peers.AprilTagProcess``: pupil-apriltags corrupted the heap here with these settings); a
  crash is reported as an error for that image and a new child serves the next images. Its time
  is measured inside the child (no inter-process transfer counted).

OpenCV (``cv2.getNumThreads()``, recorded in the JSON) and visloc (its worker thread for later
search passes) run with their default threading; AprilTag with ``nthreads=1``.

Scoring, per image and method: an expected marker is found when a detection has its id and its
centre lies within max(4 px, 0.25 x marker side) of the reference centre (each reference and each
detection matched at most once, nearest first; duplicate ids, e.g. cube faces, are separate
references). Reference centres/sides come from the reference corners, else (field set) the
labelled bbox. For the ChArUco photos the manifest has ids but no positions: matched by id only.
Detections matching nothing are false positives, except inside regions the field manifest marks
as not expected (an unreadable edge-on face): those are counted as ignored; and on the NASA
photos, whose reference is only what AprilTag 3 found (cube faces it missed are real tags, checked
by eye), they are counted as unlabelled, not as false positives. Images without an expected list
(``gbocclusion.png``) report detections only. Corner distance: per corner, Euclidean, to the
reference corners where the manifest has them: OpenCV's own integer vertices (tutorial photos),
AprilTag 3's regression output (NASA photos; stored in AprilTag's +0.5 convention, shifted by
-0.5 here), the mean of OpenCV SUBPIX and AprilTag 3 / CORNER_REFINE_APRILTAG (field set). All
are peer-derived, so they favour the peers they came from. Marker-free photos: AprilTag 3's
detections are counted unfiltered (no hamming / decision-margin threshold), as its API returns
them. Timing: ``--rounds`` rounds, every image with each method in turn
(alternating order); the table shows each image's best round (the least disturbed one: on
this 2-core machine OpenCV's two threads sometimes share one core, which makes its times
bimodal, 4.0 or 6.4 ms on one photo, and the median flip between the modes from run to run),
and ``ms total`` sums those bests. The JSON keeps every round and the median. Each timed
call starts when the host runs at its normal speed (``_timing.Steady``, checked at most every
0.25 s). 30 rounds by default. On this host (2026-12-07/08) a run took 1 min 40 s with 30 rounds
and with 15: both spent most of it waiting for the host (65 and 79 s). 30, because on this kind
of host most rounds took 1.3-1.7x the time of the photos' bests (totals over the photos), and a
best of 15 rounds depended on whether the run held a fast spell. Over five runs of 15 rounds, pairs of runs had 0-12
per-image bests more than 15 % apart (5.2 on average). Pooled two runs at a time, as bests of
30 rounds, pairs had 0-4 (0.9 on average). The five runs are kept in ``bench/results``
(``rounds-15``, ``rounds-15/later``, ``rerun``, ``rerun-2``, ``rerun-3``), and
``python bench/real_photos_rounds.py`` on them prints these counts.

Usage::

    python bench/real_photos.py [--rounds 30] [--quick] [--out bench/results]

Writes ``real_photos.json`` and ``real_photos.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from importlib.metadata import version
from pathlib import Path

import cv2
import numpy as np
from _peers import (
    APRILTAG_SETTINGS,
    AprilTagProcess,
    PeerCrashed,
    apriltag_family,
    opencv_detect,
    opencv_detector,
)
from _results import fmt, write_results
from _timing import steady

from visloc.markers import MarkerDetector

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT / "datasets/real"
METHODS = ["visloc", "opencv", "opencv_subpix", "apriltag3"]
PEERS = METHODS[1:]
NEG_DICTS = ["DICT_4X4_50", "DICT_5X5_1000", "DICT_6X6_250", "DICT_7X7_1000", "DICT_ARUCO_ORIGINAL",
             "DICT_ARUCO_MIP_36h12", "DICT_APRILTAG_16h5", "DICT_APRILTAG_25h9", "DICT_APRILTAG_36h11"]
#: scikit-image's natural photographs (no synthetic images: checkerboard, logo, phantom, horse, ...)
NEG_IMAGES = ["astronaut", "camera", "coffee", "chelsea", "rocket", "brick", "grass", "gravel", "coins",
              "moon", "page", "text", "clock", "hubble_deep_field", "immunohistochemistry", "retina",
              "microaneurysms", "cell", "stereo_motorcycle"]
#: ``datasets/real/manifest.json``'s AprilTag reference corners (NASA photos) are AprilTag's output
#: reordered to OpenCV's order but not shifted: AprilTag 3 here lands at (-0.47, -0.45) px from them
#: on average before this shift, (0.02, 0.05) after
APRILTAG_REF_SHIFT = -0.5
NEG_QUICK = ["astronaut", "camera", "coffee", "brick", "grass", "page"]


# --- images and references --------------------------------------------------------------------

def _ref(mid, corners=None, bbox=None) -> dict:
    """One expected marker: id, centre, side (px) and corners (or None)."""
    if corners is not None:
        c = np.asarray(corners, dtype=np.float64)
        return {"id": int(mid), "corners": c, "centre": c.mean(axis=0),
                "side": float(np.sqrt(abs(cv2.contourArea(c.astype(np.float32)))))}
    if bbox is not None:
        x0, y0, x1, y1 = bbox
        return {"id": int(mid), "corners": None, "centre": np.array([(x0 + x1) / 2, (y0 + y1) / 2]),
                "side": float(np.sqrt(max(x1 - x0, 1) * max(y1 - y0, 1)))}
    return {"id": int(mid), "corners": None, "centre": None, "side": None}


def load_images() -> list[dict]:
    items = []
    old = json.loads((REAL / "manifest.json").read_text())
    for im in old["images"]:
        dn = im["dictionary"]
        item = {"set": "real", "file": im["file"], "path": REAL / im["file"], "dictionary": dn,
                "dict_path": str(REAL / dn) if dn.endswith(".yml") else dn, "ignore": [], "note": None,
                "complete": True}
        if im.get("reference_detections"):
            # corners in AprilTag's convention (reordered only): shift to OpenCV's pixel centres
            item["refs"] = [_ref(d["id"], np.asarray(d["corners"]) + APRILTAG_REF_SHIFT)
                            for d in im["reference_detections"]]
            item["complete"] = False
            item["note"] = ("references are AprilTag 3's regression output, not a complete list: other "
                            "detections are counted as unlabelled, not as false positives")
        elif im.get("expected_ids"):
            rc = im.get("reference_corners") or {}
            item["refs"] = [_ref(i, rc.get(str(i))) for i in im["expected_ids"]]
            if not rc:
                item["note"] = "no reference positions: matched by id only"
        else:
            item["refs"] = None
            item["note"] = "no expected list upstream: detections only"
        items.append(item)
    field = json.loads((REAL / "field/manifest.json").read_text())
    for im in field["images"]:
        if im.get("marker_free"):
            refs = []
        else:
            refs = [_ref(m["id"], m.get("corners"), m["bbox"]) for m in im["markers"]]
        items.append({"set": "field", "file": im["file"], "path": REAL / "field" / im["file"],
                      "dictionary": im["dictionary"], "dict_path": im["dictionary"], "refs": refs,
                      "ignore": [m["bbox"] for m in im.get("missed_by_peers", []) if m.get("expected") is False],
                      "note": None, "complete": True})
    for it in items:
        img = cv2.imread(str(it["path"]), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise FileNotFoundError(it["path"])
        it["gray"] = img
        it["family"] = apriltag_family(it["dictionary"])
    return items


def match(dets, refs, ignore):
    """Greedy nearest-first matching by id and position. Returns (pairs [(det index, ref index, centre
    distance)], false-positive det indices, ignored det indices)."""
    cand = []
    for di, (mid, c) in enumerate(dets):
        centre = c.mean(axis=0)
        for ri, r in enumerate(refs):
            if r["id"] != mid:
                continue
            if r["centre"] is None:  # id-only reference
                cand.append((0.0, di, ri))
                continue
            d = float(np.linalg.norm(centre - r["centre"]))
            if d <= max(4.0, 0.25 * r["side"]):
                cand.append((d, di, ri))
    cand.sort()
    used_d, used_r, pairs = set(), set(), []
    for d, di, ri in cand:
        if di in used_d or ri in used_r:
            continue
        used_d.add(di)
        used_r.add(ri)
        pairs.append((di, ri, d))
    fp, ignored = [], []
    for di, (_, c) in enumerate(dets):
        if di in used_d:
            continue
        x, y = c.mean(axis=0)
        if any(x0 - 5 <= x <= x1 + 5 and y0 - 5 <= y <= y1 + 5 for x0, y0, x1, y1 in ignore):
            ignored.append(di)
        else:
            fp.append(di)
    return pairs, fp, ignored


# --- running ----------------------------------------------------------------------------------

class Runner:
    """The four methods for one dictionary each (detectors cached per dictionary)."""

    def __init__(self, apriltag: AprilTagProcess):
        self.at = apriltag
        self._vl, self._cv = {}, {}

    def methods_for(self, dict_path: str, family: str | None) -> list[str]:
        return METHODS if family else METHODS[:3]

    def run(self, method: str, gray, dict_path: str, family: str | None):
        """(detections, seconds); AprilTag's seconds come from the child."""
        if method == "apriltag3":
            return self.at.detect(gray, family)
        if method == "visloc":
            det = self._vl.get(dict_path) or self._vl.setdefault(dict_path, MarkerDetector(dict_path))
            t0 = time.perf_counter()
            out = det.detect(gray)
            dt = time.perf_counter() - t0
            return [(int(d.id), np.asarray(d.corners, dtype=np.float64)) for d in out], dt
        key = (dict_path, method)
        det = self._cv.get(key) or self._cv.setdefault(key, opencv_detector(dict_path, method == "opencv_subpix"))
        t0 = time.perf_counter()
        out = opencv_detect(det, gray)
        return out, time.perf_counter() - t0


def run_images(items, runner: Runner, rounds: int) -> None:
    """Fill ``item["runs"][method]`` = {"dets", "times", "errors"} with interleaved timing."""
    for it in items:
        it["runs"] = {m: {"dets": None, "times": [], "errors": []}
                      for m in runner.methods_for(it["dict_path"], it["family"])}
    for r in range(rounds):
        print(f"  round {r + 1}/{rounds}", file=sys.stderr, flush=True)
        for k, it in enumerate(items):
            order = list(it["runs"])
            if (r + k) % 2:
                order = order[::-1]
            for m in order:
                run = it["runs"][m]
                steady().wait(every=0.25)  # the host at its normal speed (bench/_timing.py)
                try:
                    dets, dt = runner.run(m, it["gray"], it["dict_path"], it["family"])
                except PeerCrashed as e:
                    run["errors"].append(f"round {r + 1}: {e}")
                    print(f"  {it['file']}: {m}: {e}", file=sys.stderr, flush=True)
                    continue
                run["times"].append(dt)
                if run["dets"] is None:
                    run["dets"] = dets
                elif len(dets) != len(run["dets"]):
                    run["errors"].append(f"round {r + 1}: {len(dets)} detections, first run {len(run['dets'])}")


def _centre(c) -> list[float]:
    return [round(float(v), 1) for v in np.asarray(c).mean(axis=0)]


def score(items) -> list[dict]:
    rows = []
    for it in items:
        refs = it["refs"]
        row = {"set": it["set"], "file": it["file"], "dictionary": it["dictionary"], "complete_labels": it["complete"],
               "size": [int(it["gray"].shape[1]), int(it["gray"].shape[0])],
               "expected": None if refs is None else len(refs), "note": it["note"], "methods": {}}
        found_by = [[] for _ in refs or []]
        for m, run in it["runs"].items():
            dets = run["dets"]
            r = {"ms_best": 1e3 * float(np.min(run["times"])) if run["times"] else None,
                 "ms_median": 1e3 * float(np.median(run["times"])) if run["times"] else None,
                 "ms_rounds": [round(1e3 * t, 3) for t in run["times"]], "errors": run["errors"]}
            if dets is None:
                r["failed"] = True
                row["methods"][m] = r
                continue
            r["detections"] = len(dets)
            if refs is None:
                r["ids"] = sorted(i for i, _ in dets)
                row["methods"][m] = r
                continue
            pairs, fp, ignored = match(dets, refs, it["ignore"])
            dist = []
            for di, ri, _ in pairs:
                found_by[ri].append(m)
                if refs[ri]["corners"] is not None:
                    dist.extend(np.linalg.norm(dets[di][1] - refs[ri]["corners"], axis=1).tolist())
            r.update({"found": len(pairs), "expected": len(refs),
                      "false_positives": len(fp) if it["complete"] else None,
                      "unlabelled": 0 if it["complete"] else len(fp), "ignored": len(ignored), "corner_dists_px": [round(d, 4) for d in dist],
                      "corner_median_px": float(np.median(dist)) if dist else None,
                      "corner_max_px": float(np.max(dist)) if dist else None,
                      "unmatched": [{"id": dets[di][0], "centre": _centre(dets[di][1])} for di in fp]})
            row["methods"][m] = r
        if refs is not None:
            row["markers"] = [{"id": ref["id"], "centre": None if ref["centre"] is None else [round(float(v), 1) for v in ref["centre"]],
                               "side_px": None if ref["side"] is None else round(ref["side"], 1),
                               "found_by": fb} for ref, fb in zip(refs, found_by)]
        rows.append(row)
    return rows


def totals(rows) -> dict:
    """Per method over all labelled images it ran on, and over the AprilTag-family images only."""
    out = {}
    scopes = {"all": lambda row: True, "tag families": lambda row: "apriltag3" in row["methods"]}
    for scope, keep in scopes.items():
        out[scope] = {}
        for m in METHODS:
            found = exp = fp = unlab = n = 0
            ms = 0.0
            dist, failed = [], 0
            for row in rows:
                if row["expected"] is None or not keep(row) or m not in row["methods"]:
                    continue
                r = row["methods"][m]
                if r.get("failed"):
                    failed += 1
                    continue
                n += 1
                found += r["found"]
                exp += r["expected"]
                fp += r["false_positives"] or 0
                unlab += r["unlabelled"]
                dist.extend(r["corner_dists_px"])
                ms += r["ms_best"] or 0.0
            if n == 0:
                continue
            out[scope][m] = {"images": n, "found": found, "expected": exp, "false_positives": fp, "unlabelled": unlab,
                             "corner_median_px": float(np.median(dist)) if dist else None,
                             "corner_p90_px": float(np.percentile(dist, 90)) if dist else None,
                             "corners_scored": len(dist), "ms_total": ms, "failed_images": failed}
    return out


def misses(rows) -> dict:
    """Expected markers visloc misses but a peer finds, those peers miss and visloc finds, and
    those nobody finds."""
    out = {"visloc_missed_peer_found": [], "peers_missed_visloc_found": [], "nobody_found": []}
    for row in rows:
        for mk in row.get("markers", []):
            e = {"file": row["file"], "id": mk["id"], "centre": mk["centre"], "side_px": mk["side_px"],
                 "found_by": mk["found_by"]}
            ran = [m for m in PEERS if m in row["methods"] and not row["methods"][m].get("failed")]
            if not mk["found_by"]:
                out["nobody_found"].append(e)
            elif "visloc" not in mk["found_by"]:
                out["visloc_missed_peer_found"].append(e)
            elif ran and not any(m in mk["found_by"] for m in ran):
                out["peers_missed_visloc_found"].append(e)
    return out


def _gray(img) -> np.ndarray:
    if img.ndim == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_RGB2GRAY)
    if img.dtype != np.uint8:
        from skimage.util import img_as_ubyte
        img = img_as_ubyte(img)
    return np.ascontiguousarray(img)


def run_negatives(runner: Runner, names, dicts) -> dict:
    """False positives on marker-free photographs (scikit-image data: public domain / CC0 or
    permissive; only images shipped with the package, nothing downloaded)."""
    from skimage import data

    images = {}
    for n in names:
        img = getattr(data, n)()
        if isinstance(img, tuple):  # stereo_motorcycle: (left, right, disparity)
            img = img[0]
        images[n] = _gray(img)
    fp = {dn: {} for dn in dicts}
    hits, errors, seconds = [], [], {m: 0.0 for m in METHODS}
    for dn in dicts:
        fam = apriltag_family(dn)
        for m in runner.methods_for(dn, fam):
            fp[dn][m] = 0
        for n, img in images.items():
            for m in runner.methods_for(dn, fam):
                try:
                    dets, dt = runner.run(m, img, dn, fam)
                except PeerCrashed as e:
                    errors.append({"image": n, "dictionary": dn, "method": m, "error": str(e)})
                    continue
                seconds[m] += dt
                fp[dn][m] += len(dets)
                hits.extend({"image": n, "dictionary": dn, "method": m, "id": i, "centre": _centre(c)} for i, c in dets)
    total = {m: sum(v.get(m, 0) for v in fp.values()) for m in METHODS}
    return {"images": {n: [int(v) for v in img.shape[::-1]] for n, img in images.items()}, "dictionaries": dicts,
            "false_positives": fp, "total": total, "detections": hits, "errors": errors,
            "ms_total": {m: 1e3 * s for m, s in seconds.items()}}


# --- report -----------------------------------------------------------------------------------

def _cell_found(r) -> str:
    if r is None:
        return "–"
    if r.get("failed"):
        return "crash"
    if "found" not in r:
        return f"{r['detections']} det"
    s = f"{r['found']}/{r['expected']}"
    if r["false_positives"]:
        s += f" +{r['false_positives']} FP"
    if r.get("unlabelled"):
        s += f" +{r['unlabelled']} unlab."
    if r.get("ignored"):
        s += f" ({r['ignored']} ign.)"
    if r["errors"]:
        s += " !"
    return s


def _cell_corner(r) -> str:
    if r is None or r.get("corner_median_px") is None:
        return "–"
    return f"{r['corner_median_px']:.2f} / {r['corner_max_px']:.2f}"


def _xy(c) -> str:
    return "–" if c is None else f"({c[0]:.0f}, {c[1]:.0f})"


def markdown(result) -> str:
    rows, tot, neg = result["images"], result["totals"], result["negatives"]
    L = [(f"**Real photographs** ({len(rows)} images: `datasets/real` and `datasets/real/field`; "
         f"{result['rounds']} round(s), shared machine: timings indicative)\n"),
         ("Found/expected: an expected marker counts when a detection has its id and its centre within "
         "max(4 px, 0.25 × side) of the reference; `+n FP` = detections matching no expected marker; "
         "`+n unlab.` = the same on the NASA photos, whose reference lists only what AprilTag 3 found "
         "(not counted as FP); `ign.` = inside a region labelled not expected; `–` = not run "
         "(AprilTag 3 only on tag families); `!` = an error or unstable run (see JSON).\n"),
         "| set | image | dictionary | size | " + " | ".join(METHODS) + " |",
         "|---|---|---|---|" + "---|" * len(METHODS)]
    for row in rows:
        cells = [_cell_found(row["methods"].get(m)) for m in METHODS]
        L.append(f"| {row['set']} | {row['file']} | {row['dictionary']} | {row['size'][0]}×{row['size'][1]} | " + " | ".join(cells) + " |")
    notes: dict[str, list[str]] = {}
    for row in rows:
        if row["note"]:
            notes.setdefault(row["note"], []).append(f"`{row['file']}`")
    if notes:
        L.append("\nNotes: " + "; ".join(f"{', '.join(files)}: {note}" for note, files in notes.items()) + ".")
    L += [("\n**Corner distance to the reference corners** (median / max px over the matched markers that have "
          "reference corners). The references are peer-derived: OpenCV default's integer vertices (tutorial "
          "photos), AprilTag 3's regression output shifted by -0.5 px (NASA photos), the mean of OpenCV SUBPIX and AprilTag 3 or "
          "CORNER_REFINE_APRILTAG (field set); they favour the peers they came from.\n"),
          "| image | " + " | ".join(METHODS) + " |", "|---|" + "---|" * len(METHODS)]
    for row in rows:
        if row["expected"] is None:
            continue
        cells = [_cell_corner(row["methods"].get(m)) for m in METHODS]
        if any(c != "–" for c in cells):
            L.append(f"| {row['file']} | " + " | ".join(cells) + " |")
    L += [(f"\n**Time** (ms per image, best of {result['rounds']} rounds; AprilTag 3 timed inside its child process; "
           "the medians are in the JSON)\n"),
          "| image | " + " | ".join(METHODS) + " |", "|---|" + "---|" * len(METHODS)]
    for row in rows:
        L.append(f"| {row['file']} | " + " | ".join(fmt((row['methods'].get(m) or {}).get('ms_best'), 2) for m in METHODS) + " |")
    L += ["\n**Totals** (labelled images; `tag families` = the images AprilTag 3 runs on, the fair comparison with it)\n",
          "| scope | method | images | found/expected | recall | FP | unlabelled | corner median px | corner p90 px | ms total |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for scope, per in tot.items():
        for m, t in per.items():
            rec = t["found"] / t["expected"] if t["expected"] else None
            crash = f" ({t['failed_images']} crashed)" if t["failed_images"] else ""
            L.append(f"| {scope} | {m} | {t['images']}{crash} | {t['found']}/{t['expected']} | {fmt(rec)} | {t['false_positives']} | {t['unlabelled']} | "
                     f"{fmt(t['corner_median_px'], 2)} | {fmt(t['corner_p90_px'], 2)} | {fmt(t['ms_total'], 1)} |")
    mis = result["misses"]
    L.append("\n**Expected markers visloc misses and a peer finds** (centre, side ≈ √area of the reference, px)\n")
    if mis["visloc_missed_peer_found"]:
        L += ["| image | id | centre (x, y) | side px | found by |", "|---|---|---|---|---|"]
        for e in mis["visloc_missed_peer_found"]:
            L.append(f"| {e['file']} | {e['id']} | {_xy(e['centre'])} | {fmt(e['side_px'], 0)} | {', '.join(e['found_by'])} |")
    else:
        L.append("None.")
    for key, title in (("peers_missed_visloc_found", "Found by visloc only (every peer that ran missed it)"),
                       ("nobody_found", "Found by no method")):
        if mis[key]:
            L.append(f"\n{title}: " + "; ".join(
                f"{e['file']} id {e['id']} at {_xy(e['centre'])} ({fmt(e['side_px'], 0)} px)" for e in mis[key]) + ".")
    for complete, title in ((True, "False positives on the labelled photos"),
                            (False, "Unlabelled detections (images whose reference is a peer's output)")):
        lst = [(row["file"], m, r["unmatched"]) for row in rows for m, r in row["methods"].items()
               if r.get("unmatched") and row["complete_labels"] is complete]
        if lst:
            L.append(f"\n{title}: " + "; ".join(
                f"{f} {m}: " + ", ".join(f"id {e['id']} at {_xy(e['centre'])}" for e in dets) for f, m, dets in lst) + ".")
    L += [(f"\n**Marker-free photos** ({len(neg['images'])} scikit-image photographs × each dictionary; "
          "every detection is a false positive)\n"),
          "| dictionary | " + " | ".join(METHODS) + " |", "|---|" + "---|" * len(METHODS)]
    for dn, per in neg["false_positives"].items():
        L.append(f"| {dn} | " + " | ".join(fmt(per.get(m)) for m in METHODS) + " |")
    L.append("| **total** | " + " | ".join(str(neg["total"][m]) for m in METHODS) + " |")
    L.append("\nImages: " + ", ".join(neg["images"]) + ".")
    if neg["detections"]:
        L.append("Detections: " + "; ".join(f"{d['method']} {d['dictionary']} id {d['id']} on {d['image']}"
                                            for d in neg["detections"]) + ".")
    if neg["errors"] or result["apriltag"]["crashes"]:
        L.append(f"\nAprilTag child crashes: {result['apriltag']['crashes']} (children started: "
                 f"{result['apriltag']['starts']}); see `errors` in the JSON.")
    return "\n".join(L) + "\n"


def _plain(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    return o.item() if hasattr(o, "item") else str(o)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=30)
    ap.add_argument("--quick", action="store_true", help="one round, 6 marker-free photos (a smoke run)")
    ap.add_argument("--out", default=str(ROOT / "bench/results"))
    args = ap.parse_args(argv)
    rounds = 1 if args.quick else args.rounds
    t_start = time.perf_counter()
    items = load_images()
    with AprilTagProcess() as at:
        runner = Runner(at)
        print(f"real photographs: {len(items)} images ...", file=sys.stderr, flush=True)
        run_images(items, runner, rounds)
        rows = score(items)
        print("marker-free photos ...", file=sys.stderr, flush=True)
        neg = run_negatives(runner, NEG_QUICK if args.quick else NEG_IMAGES, NEG_DICTS)
        at_stats = {"starts": at.starts, "crashes": at.crashes}
    result = {
        "machine": {"python": sys.version.split()[0], "opencv": cv2.__version__, "numpy": np.__version__,
                    "pupil_apriltags": version("pupil-apriltags"), "platform": platform.platform(),
                    "cv_threads": cv2.getNumThreads(), "cpus": os.cpu_count()},
        "rounds": rounds,
        "peers": {"opencv": "cv2.aruco.ArucoDetector, default DetectorParameters (cornerRefinementMethod NONE)",
                  "opencv_subpix": "cv2.aruco.ArucoDetector, DetectorParameters with cornerRefinementMethod=CORNER_REFINE_SUBPIX",
                  "apriltag3": {"pupil_apriltags.Detector": APRILTAG_SETTINGS, "corners": "corners[[1, 0, 3, 2]] - 0.5",
                                "process": "child process, time measured in the child"}},
        "apriltag": at_stats,
        "images": rows,
        "totals": totals(rows),
        "misses": misses(rows),
        "negatives": neg,
    }
    result["steady"] = steady().summary()
    result["seconds"] = time.perf_counter() - t_start
    write_results(args.out, "real_photos", result, markdown(result), default=_plain)
    print(f"({result['seconds']:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
