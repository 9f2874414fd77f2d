"""A Python re-creation of m-explore's map merger (``multirobot_map_merge``, Jiri Horner; ROS
package ``map_merge``, ``src/combine_grids``): the grid alignment robot builders use today,
so that the benchmarks can set topomerge's grid alignment beside it on the same pairs.

m-explore's estimation (``MergingPipeline::estimateTransforms``) and what reproduces each step
here (:func:`orb_merge`):

1. grids → images (``MergingPipeline::feed``): the ``int8`` occupancy data viewed as ``uint8``,
   unchanged: free 0 → 0, occupied 100 → 100, unknown −1 → 255 (:data:`STATE_TO_PIXEL`). Row 0
   is the map's bottom row (ROS stores the grid from its origin up), as in topomerge's arrays,
   so nothing is flipped: pixel ``(col, row)`` axes are the map's ``(x, y)`` axes.
2. features (``chooseFeatureFinder``, ``cv::detail::computeImageFeatures``): ``cv::ORB::create()``
   with OpenCV's defaults (``features="akaze"``: ``cv::AKAZE::create()``, the ROS node's
   default feature type, in OpenCV 4 only: OpenCV 5 moved AKAZE out of its main modules).
3. pairwise matching (``AffineBestOf2NearestMatcher(false, false, 0.3, 6)``, its ``CpuMatcher``):
   2-nearest neighbours both ways, a match kept when its distance is below ``1 − 0.3`` times the
   second's, the B→A matches not already found A→B appended. OpenCV searches with a FLANN LSH
   index (approximate, with random hash tables: ``cv2.detail``'s matcher gives different
   matches from call to call on one pair); here a brute-force Hamming search finds the exact
   neighbours, so runs repeat.
4. fewer than 6 matches: no transform, confidence 0. Otherwise ``estimateAffinePartial2D`` (A's
   points → B's, RANSAC with OpenCV's defaults: 3 px, 2000 iterations, 0.99, 10 refinement
   iterations) and the confidence ``inliers / (8 + 0.3 · matches)`` (Brown and Lowe's rule).
5. ``leaveBiggestComponent(features, matches, confidence)``: for two maps, they are merged when
   ``confidence >= confidence_threshold`` (``estimation_confidence``, 1.0 in the ROS node).
6. ``AffineBasedEstimator`` chains the pairwise transforms (for two maps: A the identity, B the
   A→B transform), so B's cells go into A's frame by its inverse (``GridWarper::warp``).
   ``BundleAdjusterAffinePartial`` then refines the same inlier reprojection error that step 4's
   refinement already minimised; it is left out.

:func:`orb_rigid` runs it on two :class:`fusion.mapmerge.InputMap` and turns the pixel
transform (a similarity: m-explore keeps its scale) into a metric :class:`fusion.rigid.Rigid2D`.

Needs OpenCV: the ``bench`` extra (``pip install 'topomerge[bench]'``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from fusion.mapmerge import InputMap, resampled
from fusion.rigid import Rigid2D
from topo.grid import CellState
from topo.validation import check_int, check_real

_ROS_VALUE = {CellState.UNKNOWN: 255, CellState.FREE: 0, CellState.OCCUPIED: 100}
STATE_TO_PIXEL = np.array([_ROS_VALUE[s] for s in sorted(CellState)], dtype=np.uint8)
"""Pixel value of each :class:`topo.CellState` code (read-only): a ROS grid's ``int8`` value
(unknown −1, free 0, occupied 100) read as ``uint8``, m-explore's view of the grid."""
STATE_TO_PIXEL.setflags(write=False)

MATCH_CONF = 0.3
"""``AffineBestOf2NearestMatcher``'s ``match_conf``: the ratio test keeps ``d1 < (1 − 0.3) d2``."""
MIN_MATCHES = 6
"""``num_matches_thresh1``: fewer matches and no transform is estimated."""
FEATURES = ("orb", "akaze")
"""Feature finders of m-explore (its SURF needs OpenCV's non-free module, left out)."""


def _cv2():
    try:
        import cv2
    except ImportError as exc:
        raise ImportError("benchmarks/_orb.py needs OpenCV: pip install 'topomerge[bench]'"
                          ) from exc
    return cv2


@dataclass(frozen=True, slots=True, eq=False)
class OrbResult:
    """What :func:`orb_merge` found.

    Attributes:
        transform: ``(2, 3)`` affine taking B's pixel coordinates ``(col, row)`` to A's (a
            similarity), the estimate even when not accepted; ``None`` when none was estimated
            (too few matches, or RANSAC found no model).
        confidence: ``inliers / (8 + 0.3 · matches)`` (0 without a transform).
        accepted: a transform with ``confidence >= confidence_threshold``: m-explore would
            merge the maps.
        matches: matches that passed the ratio test.
        inliers: RANSAC inliers among them.
        seconds: wall time of the call.
    """

    transform: np.ndarray | None
    confidence: float
    accepted: bool
    matches: int
    inliers: int
    seconds: float


@dataclass(frozen=True, slots=True, eq=False)
class OrbRigid:
    """What :func:`orb_rigid` found.

    Attributes:
        transform: B's grid frame → A's grid frame, metres (as
            :func:`fusion.grid_merge.merge_grids` gives it), the estimate even when not
            accepted; ``None`` when none was estimated.
        confidence: m-explore's confidence (:class:`OrbResult`).
        accepted: whether m-explore would merge the maps.
        scale: scale of the pixel transform (1 for a perfect estimate; ``nan`` without one).
            m-explore does not look at it: a RANSAC model that shrinks many matches of one
            map onto a few pixels of the other can pass its confidence rule.
        pixel: the :class:`OrbResult` on the maps' images.
        seconds: wall time of the call (images, resampling and :func:`orb_merge`).
    """

    transform: Rigid2D | None
    confidence: float
    accepted: bool
    scale: float
    pixel: OrbResult
    seconds: float


def _image(value: object, name: str) -> np.ndarray:
    if not isinstance(value, np.ndarray):
        raise TypeError(f"{name} must be a numpy array (uint8 image), got {type(value).__name__}")
    if value.ndim != 2 or value.dtype != np.uint8:
        raise ValueError(f"{name} must be a 2-D uint8 image, got shape {value.shape} and dtype "
                         f"{value.dtype}")
    return np.ascontiguousarray(value)


def _ratio_matches(matcher, desc_1: np.ndarray, desc_2: np.ndarray) -> list[tuple[int, int]]:
    """``CpuMatcher::match``: ``(index in 1, index in 2)`` pairs passing the ratio test 1→2,
    then those passing it 2→1 that 1→2 did not find."""
    pairs: list[tuple[int, int]] = []
    for m in matcher.knnMatch(desc_1, desc_2, k=2):
        if len(m) == 2 and m[0].distance < (1.0 - MATCH_CONF) * m[1].distance:
            pairs.append((m[0].queryIdx, m[0].trainIdx))
    found = set(pairs)
    for m in matcher.knnMatch(desc_2, desc_1, k=2):
        if len(m) == 2 and m[0].distance < (1.0 - MATCH_CONF) * m[1].distance:
            pair = (m[0].trainIdx, m[0].queryIdx)
            if pair not in found:
                pairs.append(pair)
    return pairs


def orb_merge(image_a: np.ndarray, image_b: np.ndarray, *, confidence_threshold: float = 1.0,
              seed: int = 0, features: str = "orb") -> OrbResult:
    """m-explore's estimation of B's transform into A on two occupancy images (module
    docstring, steps 2-6).

    Args:
        image_a, image_b: ``uint8`` images as m-explore sees grids (:data:`STATE_TO_PIXEL`).
        confidence_threshold: m-explore's ``estimation_confidence`` (``>= 0``).
        seed: given to ``cv2.setRNGSeed`` (OpenCV's global generator) before RANSAC. OpenCV's
            RANSAC seeds a generator of its own with a constant, so the result does not depend
            on it: the call repeats exactly whatever the seed.
        features: ``"orb"`` or ``"akaze"``.

    Returns:
        an :class:`OrbResult`.

    Raises:
        TypeError, ValueError: an image that is not a 2-D ``uint8`` array, a negative threshold,
            a negative seed or an unknown feature finder, naming the parameter.
        ImportError: OpenCV is not installed (naming the extra), or has no AKAZE.
    """
    t0 = time.perf_counter()
    a, b = _image(image_a, "image_a"), _image(image_b, "image_b")
    threshold = check_real(confidence_threshold, "confidence_threshold", low=0.0,
                           low_inclusive=True)
    seed = check_int(seed, "seed", low=0)
    if features not in FEATURES:
        raise ValueError(f"features must be one of {FEATURES}, got {features!r}")
    cv2 = _cv2()
    if features == "akaze" and not hasattr(cv2, "AKAZE_create"):
        raise ImportError(f"features='akaze' needs an OpenCV with AKAZE (4.x); OpenCV "
                          f"{cv2.__version__} has none")
    finder = cv2.ORB_create() if features == "orb" else cv2.AKAZE_create()
    kp_a, desc_a = finder.detectAndCompute(a, None)
    kp_b, desc_b = finder.detectAndCompute(b, None)
    pairs: list[tuple[int, int]] = []
    if desc_a is not None and desc_b is not None:
        pairs = _ratio_matches(cv2.BFMatcher(cv2.NORM_HAMMING), desc_a, desc_b)
    if len(pairs) < MIN_MATCHES:
        return OrbResult(None, 0.0, False, len(pairs), 0, time.perf_counter() - t0)
    src = np.array([kp_a[i].pt for i, _ in pairs], dtype=np.float32)
    dst = np.array([kp_b[j].pt for _, j in pairs], dtype=np.float32)
    cv2.setRNGSeed(seed)
    a_to_b, mask = cv2.estimateAffinePartial2D(src, dst, method=cv2.RANSAC)
    if a_to_b is None:
        return OrbResult(None, 0.0, False, len(pairs), 0, time.perf_counter() - t0)
    inliers = int(np.count_nonzero(mask))
    confidence = inliers / (8.0 + 0.3 * len(pairs))
    b_to_a = cv2.invertAffineTransform(a_to_b)
    return OrbResult(b_to_a, confidence, confidence >= threshold, len(pairs), inliers,
                     time.perf_counter() - t0)


def grid_image(m: InputMap) -> np.ndarray:
    """The ``uint8`` image m-explore makes of ``m``'s grid (row 0 its bottom row)."""
    return STATE_TO_PIXEL[np.asarray(m.states, dtype=np.intp)]


def orb_rigid(map_a: InputMap, map_b: InputMap, *, confidence_threshold: float = 1.0,
              seed: int = 0, features: str = "orb") -> OrbRigid:
    """m-explore's alignment of ``map_b`` onto ``map_a``, as a metric rigid motion.

    B is first resampled to A's resolution (:func:`fusion.mapmerge.resampled`; m-explore
    matches pixels and assumes one resolution). Pixel ``(u, v)`` of a map is the point
    ``origin + resolution · ((u, v) + 0.5)`` of its grid frame (OpenCV puts pixel centres at
    integer coordinates). The similarity's rotation is kept and its scale dropped: the
    translation makes the rigid motion agree with the similarity at B's known cells' centre.

    Args:
        map_a, map_b: the maps (:func:`fusion.mapmerge.load_input`).
        confidence_threshold, seed, features: as :func:`orb_merge`.

    Returns:
        an :class:`OrbRigid` (B's grid frame → A's grid frame).

    Raises:
        TypeError: a map that is not an :class:`fusion.mapmerge.InputMap`.
        ValueError, ImportError: as :func:`orb_merge`.
    """
    t0 = time.perf_counter()
    for name, m in (("map_a", map_a), ("map_b", map_b)):
        if not isinstance(m, InputMap):
            raise TypeError(f"{name} must be a fusion.mapmerge.InputMap, got {type(m).__name__}")
    b = resampled(map_b, map_a.resolution)
    pixel = orb_merge(grid_image(map_a), grid_image(b), confidence_threshold=confidence_threshold,
                      seed=seed, features=features)
    if pixel.transform is None:
        return OrbRigid(None, pixel.confidence, pixel.accepted, math.nan, pixel,
                        time.perf_counter() - t0)
    lin, off = pixel.transform[:, :2], pixel.transform[:, 2]
    o_a, o_b = np.asarray(map_a.origin, dtype=np.float64), np.asarray(b.origin, dtype=np.float64)
    res = map_a.resolution

    def to_a(p: np.ndarray) -> np.ndarray:  # B's grid frame → A's, through the pixel transform
        return o_a + res * (lin @ ((p - o_b) / res - 0.5) + off + 0.5)

    theta = math.atan2(lin[1, 0] - lin[0, 1], lin[0, 0] + lin[1, 1])
    centre = b.centre()
    rot = Rigid2D(theta)
    transform = Rigid2D(theta, to_a(centre) - rot.apply(centre))
    scale = float(math.sqrt(abs(np.linalg.det(lin))))
    return OrbRigid(transform, pixel.confidence, pixel.accepted, scale, pixel,
                    time.perf_counter() - t0)
