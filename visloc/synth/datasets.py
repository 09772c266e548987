"""Write synthetic marker datasets to disk: PNG frames or an MP4 video, plus ground truth.

Layout of a dataset directory::

    frame_0000.png, frame_0001.png, ...   8-bit grey images
    ground_truth.json                     see :func:`render_dataset`
    camera.yml                            OpenCV FileStorage: camera_matrix,
                                          distortion_coefficients, image_width, image_height
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from visloc._checks import check_int
from visloc.markers.dictionary import Dictionary, load_dictionary
from visloc.synth._checks import check_camera, check_number, check_size
from visloc.synth.markers import MarkerRender, render_markers
from visloc.synth.scenes import DIFFICULTIES, MARKER_LENGTH, default_camera, random_scene
from visloc.synth.textures import make_background
from visloc.types import Pose

FloatArray = NDArray[np.float64]

#: Lens distortion ``(k1, k2)`` of the camera-like frames of :func:`render_dataset` (a webcam's
#: mild barrel distortion, :class:`~visloc.synth.camera.CameraEffects`' default).
DATASET_LENS = (-0.05, 0.0)
# Distance (m) between neighbouring markers along the row of :func:`render_video`.
_VIDEO_SPACING = 0.5


def write_camera_yml(path: str | Path, K: FloatArray, size: tuple[int, int],
                     dist: FloatArray | None = None) -> Path:
    """Write an OpenCV FileStorage YAML camera file.

    Parameters
    ----------
    path : str or Path
        Output file (overwritten; its folder must exist).
    K : ndarray (3, 3)
        Camera matrix, px (OpenCV's pixel convention: pixel centres at integer coordinates),
        written as ``camera_matrix``.
    size : (int, int)
        ``(width, height)`` of the images, px (``image_width``, ``image_height``).
    dist : ndarray (n,) or None
        OpenCV distortion coefficients (``k1, k2, p1, p2[, k3 ...]``), written as a 1 x n
        ``distortion_coefficients``; ``None``: five zeros.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    TypeError, ValueError
        ``K``, ``size`` or ``dist`` malformed (``K`` as :func:`visloc.synth._checks.check_camera`
        checks it; ``dist`` not 4 to 14 finite numbers), or ``path``'s folder missing (before,
        OpenCV's own error); the message names the argument. Nothing is written then.
    """
    path = Path(path)
    k = check_camera(K)
    w, h = check_size(size)
    try:
        coeffs = np.zeros(5) if dist is None else np.asarray(dist, np.float64).ravel()
    except (TypeError, ValueError) as exc:
        raise TypeError(f"dist: expected numbers, got {type(dist).__name__}") from exc
    if not 4 <= coeffs.size <= 14 or not np.all(np.isfinite(coeffs)):
        raise ValueError(f"dist: expected 4 to 14 finite coefficients, got {coeffs.tolist()!r}")
    if not path.parent.is_dir():
        raise ValueError(f"path: folder {path.parent} does not exist")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    if not fs.isOpened():
        raise ValueError(f"path: cannot write {path}")
    try:
        fs.write("image_width", w)
        fs.write("image_height", h)
        fs.write("camera_matrix", k)
        fs.write("distortion_coefficients", coeffs.reshape(1, -1))
    finally:
        fs.release()
    return path


def _frame_record(name: str, render: MarkerRender) -> dict:
    return {
        "file": name,
        "params": dict(render.params),
        "markers": [m.to_dict() for m in render.markers],
    }


def _header(dic: Dictionary, size: tuple[int, int], K: FloatArray, length: float) -> dict:
    return {
        "dictionary": dic.name,
        "size": [int(size[0]), int(size[1])],
        "camera": {"K": np.asarray(K).tolist(), "dist": [0.0] * 5},
        "marker_length": float(length),
    }


def _check_progress(progress: object) -> None:
    if progress is not None and not callable(progress):
        raise TypeError(f"progress must be a callable or None, got {type(progress).__name__}")


def render_dataset(
    outdir: str | Path,
    n: int,
    *,
    seed: int = 1,
    size: tuple[int, int] = (640, 480),
    dictionary: str | Dictionary = "DICT_4X4_50",
    difficulty: str = "easy",
    camera: bool = True,
    progress: Callable[[int], object] | None = None,
) -> Path:
    """Render ``n`` random scenes to ``outdir`` with ground truth and a camera file.

    Frame ``i`` is ``random_scene(np.random.default_rng([seed, i]), ...)``, so it does not
    depend on ``n``. With ``camera`` (the default) the frames are camera-like (random
    :class:`~visloc.synth.camera.CameraEffects` per frame, sRGB-encoded) through one lens,
    :data:`DATASET_LENS`, which ``camera.yml`` records; without, they are linear renders.

    Parameters
    ----------
    outdir : str or Path
        Directory to write into (created if missing; existing files are overwritten).
    n : int
        Number of frames (>= 1).
    seed : int
        Seed of the dataset.
    size : (int, int)
        ``(width, height)``, px (as in :func:`~visloc.synth.scenes.random_scene`).
    dictionary : str or Dictionary
        Marker dictionary (as in :func:`~visloc.synth.scenes.random_scene`).
    difficulty : {'easy', 'hard', 'small', 'empty', 'dark'}
        As in :func:`~visloc.synth.scenes.random_scene`.
    camera : bool
        Camera-like frames (``True``) or linear renders.
    progress : callable or None
        Called as ``progress(i)`` after frame ``i`` is written. An exception it raises (or a
        Ctrl-C) stops the run; ``ground_truth.json`` and ``camera.yml`` then cover the frames
        written so far.

    Returns
    -------
    Path
        ``outdir``. ``ground_truth.json`` holds ``dictionary``, ``size`` ``[w, h]``,
        ``camera`` ``{"K", "dist"}``, ``marker_length``, ``difficulty``, ``seed`` and
        ``frames``: per frame ``file``, ``params`` and ``markers`` (``id``, ``corners`` (4 x
        [x, y], OpenCV order), ``rvec``, ``tvec``, ``length``, ``visible``).

    Raises
    ------
    TypeError, ValueError
        On a malformed argument; the message names it.
    OSError
        If a frame cannot be written.
    """
    n = check_int(n, "n", low=1)
    seed = check_int(seed, "seed", low=0)
    w, h = check_size(size)
    if difficulty not in DIFFICULTIES:
        raise ValueError(f"difficulty must be one of {DIFFICULTIES}, got {difficulty!r}")
    _check_progress(progress)
    dic = load_dictionary(dictionary)
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    K = default_camera((w, h))
    gt = _header(dic, (w, h), K, MARKER_LENGTH) | {"difficulty": difficulty, "seed": seed}
    frames: list[dict] = []
    dist = np.array([*DATASET_LENS, 0.0, 0.0, 0.0]) if camera else np.zeros(5)
    gt["camera"]["dist"] = dist.tolist()
    gt["camera_like"] = bool(camera)
    try:
        for i in range(n):
            frames.append(_write_frame(out, i, seed, (w, h), dic, difficulty, camera))
            if progress is not None:
                progress(i)
    finally:  # interrupted or failed: the frames written so far keep their ground truth
        if frames:
            _write_ground_truth(out, gt, frames, K, (w, h), dist)
    return out


def _write_frame(out: Path, i: int, seed: int, size: tuple[int, int], dic: Dictionary,
                 difficulty: str, camera: bool) -> dict:
    """Render frame ``i`` of a :func:`render_dataset` data set, write it to ``out`` as
    ``frame_<i>.png`` and return its ground-truth record."""
    lens = DATASET_LENS if camera else None
    render = random_scene(np.random.default_rng([seed, i]), size=size, dictionary=dic,
                          difficulty=difficulty, camera=camera, lens=lens)
    name = f"frame_{i:04d}.png"
    if not cv2.imwrite(str(out / name), render.image):
        raise OSError(f"could not write {out / name}")
    return _frame_record(name, render)


def _write_ground_truth(out: Path, gt: dict, frames: list[dict], K: FloatArray,
                        size: tuple[int, int], dist: FloatArray) -> None:
    """Write ``ground_truth.json`` (``gt`` with the ``frames`` records) and ``camera.yml`` of a
    :func:`render_dataset` data set to ``out``."""
    gt["frames"] = frames
    (out / "ground_truth.json").write_text(json.dumps(gt, indent=1))
    write_camera_yml(out / "camera.yml", K, size, dist)


def _ground_background(K: FloatArray, T_cam_world: Pose, size: tuple[int, int],
                       texture: FloatArray, texel: float) -> FloatArray:
    """The ground plane ``Z = 0`` (world frame), textured, seen by the camera."""
    th, tw = texture.shape
    # Texture pixel (u, v) sits at world (X, Y) = ((u - tw/2) * texel, (th/2 - v) * texel).
    tex_to_world = np.array([[texel, 0.0, -0.5 * tw * texel], [0.0, -texel, 0.5 * th * texel],
                             [0.0, 0.0, 1.0]])
    R, t = T_cam_world.R, T_cam_world.t
    world_to_img = K @ np.c_[R[:, 0], R[:, 1], t]
    return cv2.warpPerspective(texture, world_to_img @ tex_to_world, size,
                               flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def render_video(
    path: str | Path,
    n: int,
    *,
    seed: int = 1,
    size: tuple[int, int] = (320, 240),
    dictionary: str | Dictionary = "DICT_4X4_50",
    n_markers: int = 4,
    fps: float = 30.0,
    ground_truth: str | Path | None = None,
    progress: Callable[[int], object] | None = None,
) -> Path:
    """Render a video of a camera flying smoothly over markers lying on textured ground.

    The camera looks down from about 0.8 m and moves along a row of ``n_markers`` markers
    (side :data:`MARKER_LENGTH`, 0.5 m apart, random ids and yaw) from before the first to
    past the last, with slow sinusoidal roll, pitch, yaw and height changes. Frames are clean
    (blur sigma 0.5 px, noise 1.5); the MP4 codec adds its own loss.

    Parameters
    ----------
    path : str or Path
        Output video file (``.mp4``, codec ``mp4v``).
    n : int
        Number of frames (>= 2).
    seed : int
        Seed of the marker layout, background and noise.
    size : (int, int)
        ``(width, height)``, px.
    dictionary : str or Dictionary
        Marker dictionary.
    n_markers : int
        Number of markers (1 to the dictionary size).
    fps : float
        Frame rate written into the video and used for the frame times.
    ground_truth : str, Path or None
        Where to write the ground truth; default ``ground_truth.json`` beside the video.
    progress : callable or None
        Called as ``progress(i)`` after frame ``i`` is written. An exception it raises (or a
        Ctrl-C) stops the run; the video then holds the frames written so far and no ground
        truth is written.

    Returns
    -------
    Path
        ``path``. The ground truth has the form of :func:`render_dataset`'s; each frame
        record has ``file`` ``"<video name>#<i>"``, ``index``, ``time`` (s), and markers
        outside the view are listed with ``visible: false``.

    Raises
    ------
    TypeError, ValueError
        On a malformed argument; the message names it.
    OSError
        If the video cannot be opened for writing.
    """
    n, seed, (w, h), dic, n_markers, fps = _check_video_args(n, seed, size, dictionary,
                                                              n_markers, fps, progress)
    path = Path(path)
    gt_path = Path(ground_truth) if ground_truth is not None else path.parent / "ground_truth.json"
    rng = np.random.default_rng(seed)
    K = default_camera((w, h))
    layout = _video_layout(rng, len(dic), n_markers)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h), isColor=False)
    if not writer.isOpened():
        raise OSError(f"could not open {path} for writing an mp4v video")
    gt = _header(dic, (w, h), K, MARKER_LENGTH) | {"seed": seed, "video": path.name, "fps": fps}
    frames = []
    try:
        for i in range(n):
            render = _video_frame(K, (w, h), dic, layout, i / (n - 1), rng)
            writer.write(render.image)
            frames.append(_video_record(path.name, i, fps, render))
            if progress is not None:
                progress(i)
    finally:
        writer.release()
    gt["frames"] = frames
    gt_path.write_text(json.dumps(gt, indent=1))
    return path


def _check_video_args(n: object, seed: object, size: object, dictionary: str | Dictionary,
                      n_markers: object, fps: object, progress: object
                      ) -> tuple[int, int, tuple[int, int], Dictionary, int, float]:
    """:func:`render_video`'s arguments checked in order; returns ``n``, ``seed``,
    ``(width, height)``, the dictionary, ``n_markers`` and ``fps``."""
    n = check_int(n, "n", low=2)
    seed = check_int(seed, "seed", low=0)
    w, h = check_size(size)
    dic = load_dictionary(dictionary)
    n_markers = check_int(n_markers, "n_markers", low=1, high=len(dic))
    fps = check_number(fps, "fps", low=0.0, low_open=True)
    _check_progress(progress)
    return n, seed, (w, h), dic, n_markers, fps


class _VideoLayout(NamedTuple):
    """The random scene of :func:`render_video`."""

    ids: NDArray[np.int64]  # marker ids, in order along the row
    T_world_marker: list[Pose]  # marker-to-world poses (world Z up, ground Z = 0)
    texture: NDArray[np.float32]  # ground texture, grey levels
    phase: FloatArray  # (4,) phases of the camera's wobble, rad


def _video_layout(rng: np.random.Generator, n_ids: int, n_markers: int) -> _VideoLayout:
    """Draw :func:`render_video`'s scene: ``n_markers`` distinct ids out of ``n_ids`` in a row
    along world x, :data:`_VIDEO_SPACING` apart with random yaw and sideways offset, the
    ground texture and the phases of the camera's wobble."""
    ids = rng.choice(n_ids, size=n_markers, replace=False)
    T_world_marker = [
        Pose(_rot_z(rng.uniform(0, 2 * np.pi)),
             np.array([k * _VIDEO_SPACING, rng.uniform(-0.12, 0.12), 0.0]))
        for k in range(n_markers)
    ]
    texture, _ = make_background("noise", (512, 512), rng)
    phase = rng.uniform(0, 2 * np.pi, 4)
    return _VideoLayout(ids, T_world_marker, texture.astype(np.float32), phase)


def _video_camera(s: float, phase: FloatArray, n_markers: int) -> Pose:
    """World-to-camera pose ``T_cam_world`` at fraction ``s`` in [0, 1] of the flight along the
    row of ``n_markers`` markers."""
    wob = np.sin(2 * np.pi * s + phase)
    # Camera position in the world (Z up) and attitude: looking straight down, then
    # small yaw / pitch / roll; T_cam_world maps world points into the camera frame.
    centre = np.array([-0.6 + s * ((n_markers - 1) * _VIDEO_SPACING + 1.2), 0.08 * wob[0],
                       0.8 + 0.05 * wob[1]])
    R_world_cam = _rot_z(0.15 * wob[2]) @ _rot_x(np.pi + 0.05 * wob[3])
    return Pose(R_world_cam.T, -R_world_cam.T @ centre)


def _video_frame(K: FloatArray, size: tuple[int, int], dic: Dictionary, layout: _VideoLayout,
                 s: float, rng: np.random.Generator) -> MarkerRender:
    """Render :func:`render_video`'s frame at fraction ``s`` of the flight: the markers over
    the textured ground, clean (blur sigma 0.5 px, noise 1.5)."""
    T_cam_world = _video_camera(s, layout.phase, len(layout.ids))
    bg = _ground_background(K, T_cam_world, size, layout.texture, 0.004)
    placements = [(int(mid), T_cam_world.compose(T), MARKER_LENGTH)
                  for mid, T in zip(layout.ids, layout.T_world_marker, strict=True)]
    return render_markers(K, size, placements, dic,
                          background=np.clip(np.rint(bg), 0, 255).astype(np.uint8),
                          blur_sigma=0.5, noise_sigma=1.5, rng=rng)


def _video_record(video_name: str, i: int, fps: float, render: MarkerRender) -> dict:
    """Ground-truth record of frame ``i`` of a video (:func:`render_video`)."""
    rec = _frame_record(f"{video_name}#{i}", render)
    rec["params"]["background"] = "noise (ground plane)"
    return {"index": i, "time": i / fps} | rec


def _rot_z(angle: float) -> FloatArray:
    """Rotation matrix about z by ``angle`` rad."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_x(angle: float) -> FloatArray:
    """Rotation matrix about x by ``angle`` rad."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
