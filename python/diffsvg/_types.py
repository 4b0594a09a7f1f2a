"""The dicts diffsvg returns and passes to progress callbacks, as ``TypedDict``s (for type
checkers and readers; at run time they are plain dicts)."""

from __future__ import annotations

import sys
from typing import Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

if sys.version_info >= (3, 11):
    from typing import NotRequired, TypedDict
else:  # pragma: no cover - typing_extensions ships with every type checker
    from typing import TypedDict
    NotRequired = Optional

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]


class Owner(TypedDict):
    """Who a slot of ``Scene.params()`` belongs to."""
    id: str
    kind: str  # "path" or "group"


class Layout(TypedDict):
    """``Scene.layout()``: per slot its group and owner."""
    group: npt.NDArray[np.uint8]
    owner: npt.NDArray[np.uint32]
    group_names: List[str]
    owners: List[Owner]


class PaintEntry(TypedDict):
    """Where a paint's values lie: ``len`` slots from ``offset`` (paint values, then the
    opacity); gradients give the count of geometry values and of stops."""
    kind: str  # "solid", "linear", "radial" or "image"
    offset: int
    len: int
    geometry: NotRequired[int]
    stops: NotRequired[int]


class PrimitiveEntry(TypedDict):
    """Where a circle's, ellipse's or rectangle's own parameters lie: from ``offset``,
    one run per field, in order."""
    kind: str  # "circle", "ellipse" or "rect"
    offset: int
    fields: List[Tuple[str, int]]  # (name, length): center, radius, corner, size, radii, angle


class GradientPaint(TypedDict, total=False):
    """A gradient for the scene builder (``Scene.add_path``, ``add_circle``, …), in
    pixels: ``kind`` "linear" (``geometry`` x1, y1, x2, y2) or "radial" (cx, cy, r, fx,
    fy, fr), ``stops`` rows of (offset, r, g, b, opacity), ``opacity`` (default 1) and
    ``spread`` ("pad", "reflect", "repeat")."""
    kind: str
    geometry: Sequence[float]
    stops: Sequence[Sequence[float]]
    opacity: float
    spread: str


class ShapeEntry(TypedDict):
    """One path of ``Scene.structure()``."""
    id: str
    points: Tuple[int, int]  # offset, count (0 for a primitive)
    primitive: Optional[PrimitiveEntry]
    segments: List[int]
    closed: List[bool]
    kinds: List[str]  # per subpath, one letter per segment as written: "LCQ"
    fill: Optional[PaintEntry]
    stroke: Optional[PaintEntry]
    stroke_width: Optional[int]


class GroupEntry(TypedDict):
    """One group of ``Scene.structure()``: its opacity's slot."""
    id: str
    offset: int


class FilterEntry(TypedDict):
    """One filtered group of ``Scene.structure()``: its filters' slots."""
    id: str
    offset: int
    len: int


class Structure(TypedDict):
    """``Scene.structure()``: ``transforms`` holds each group transform's first slot
    (``tx, ty, angle, scale`` follow), ``filters`` each filtered group's filter
    parameters."""
    shapes: List[ShapeEntry]
    groups: List[GroupEntry]
    transforms: List[GroupEntry]
    filters: List[FilterEntry]


class FitInfo(TypedDict):
    """What ``fit`` returns beside the scene."""
    loss: float
    psnr: float
    steps: int
    reason: str
    step_ms: float
    final_loss: Optional[float]
    seconds: Optional[float]
    history: F64  # rows of iter, loss, psnr, seconds
    background: Optional[List[float]]  # the fitted background, straight RGBA


class VectorizeInfo(TypedDict):
    """What ``vectorize`` returns beside the scene."""
    psnr: float
    mse: float
    steps: int
    rounds: int
    pruned: int
    seconds: float
    step_ms: float


class DigitInfo(TypedDict):
    """What ``digit`` returns beside the scene."""
    iou: float
    mse: float
    segments: List[int]
    steps: int


class GlyphInfo(TypedDict):
    """What ``glyph`` returns beside the scene."""
    iou: float
    mse: float
    segments: int
    reached: bool
    steps: int
    seconds: float


class ReconInfo(TypedDict):
    """What ``recon_voxel``, ``recon_splat``, ``recon_ngp`` and ``recon_nerf`` return."""
    output: str
    iterations: int
    stopped: bool
    seconds: float
    load_seconds: float
    test_psnr: Optional[float]
    log: F64
    res: NotRequired[int]
    allocated: NotRequired[int]
    batch: NotRequired[int]
    gaussians: NotRequired[int]
    undistorted: NotRequired[Optional[float]]
    samples: NotRequired[int]
    samples_per_second: NotRequired[float]
    parameters: NotRequired[int]
    occupied: NotRequired[float]
    pose_error: Optional[Dict[str, Tuple[float, float]]]
    test_psnr_in_frame: NotRequired[Optional[float]]
    test_psnr_aligned: NotRequired[Optional[float]]
    test_pose_turn: NotRequired[Optional[float]]


class Depth(TypedDict):
    """A view's depth images: ``(h, w)`` ``float32``, world units along the viewing axis."""
    expected: F32
    median: F32


class Views(TypedDict, total=False):
    """What ``view`` returns: ``(name, rendering, photo)`` per view and the orbit; with
    ``depth=True`` also their depth images, in the same order."""
    views: List[Tuple[str, F32, F32]]
    orbit: List[F32]
    depth: List[Depth]
    orbit_depth: List[Depth]


Step = dict
"""A progress report: ``iter``, ``loss``, ``psnr``, ``seconds`` (and more per job)."""

Progress = Optional[Callable[[Step], object]]
"""A progress callback: returning ``False`` stops the run; other values are ignored."""

Info = Union[FitInfo, VectorizeInfo, DigitInfo, GlyphInfo]

Array = npt.NDArray[np.floating]


class PaintArrays(TypedDict, total=False):
    """A gradient's (``geometry``, ``stops``, ``opacity``) or an image's (``opacity``)
    arrays in ``Scene.arrays()``."""
    geometry: Array
    stops: Array
    opacity: Array


class ShapeArrays(TypedDict, total=False):
    """One shape of ``Scene.arrays()``; keys absent when the shape has no such paint. A
    path has ``points``; a circle ``center`` and ``radius``; an ellipse ``center``,
    ``radius`` (rx, ry) and ``angle``; a rectangle ``corner``, ``size``, ``radii`` (rounded
    corners only) and ``angle``."""
    points: Array
    center: Array
    radius: Array
    corner: Array
    size: Array
    radii: Array
    angle: Array
    fill: Union[Array, PaintArrays]
    stroke: Union[Array, PaintArrays]
    stroke_width: Array


class GroupArrays(TypedDict):
    """One group of ``Scene.arrays()``."""
    opacity: Array


class TransformArrays(TypedDict):
    """One group transform of ``Scene.arrays()``: pixels, radians, a factor."""
    translate: Array
    angle: Array
    scale: Array


class Arrays(TypedDict):
    """``Scene.arrays()``: the parameters per shape and group, as DiffVG names them
    (``transforms`` only where groups' transforms are parameters, ``filters`` where
    filters have parameters)."""
    shapes: List[ShapeArrays]
    groups: List[GroupArrays]
    transforms: NotRequired[List[TransformArrays]]
    filters: NotRequired[List[dict]]


class GradJson(TypedDict):
    """``Scene.grad_json()``: the layout of ``diffsvg grad --json``."""
    shapes: List[dict]
    groups: List[dict]
    transforms: NotRequired[List[dict]]
    filters: NotRequired[List[dict]]


MeshLight = Tuple[Tuple[float, float, float], Tuple[float, float, float]]
"""A directional light for ``Mesh.render``: (world direction towards the light, RGB
intensity)."""


class MeshGrad(TypedDict):
    """``Mesh.render_backward``: the loss's gradient per vertex position ``(n, 3)``, of a
    camera pose correction ``pose`` ``(6,)`` (rotation vector, then translation, world
    axes), per vertex color ``(n, 3)``, texel ``(h, w, 3)`` and UV ``(n, 2)`` when the mesh
    has them, and when lit of ``ambient`` ``(3,)``, ``light_directions`` and
    ``light_intensities`` ``(k, 3)``."""
    positions: npt.NDArray[np.float64]
    pose: npt.NDArray[np.float64]
    colors: NotRequired[npt.NDArray[np.float64]]
    texture: NotRequired[npt.NDArray[np.float64]]
    uvs: NotRequired[npt.NDArray[np.float64]]
    ambient: NotRequired[npt.NDArray[np.float64]]
    light_directions: NotRequired[npt.NDArray[np.float64]]
    light_intensities: NotRequired[npt.NDArray[np.float64]]


class MeshStep(TypedDict):
    """What ``Mesh.fit``'s progress callback gets each step: the step (from 0) and the
    training views' mean squared error before it."""
    iter: int
    mse: float


#: ``Mesh.fit``'s callback; returning ``False`` stops the fit.
MeshProgress = Callable[[MeshStep], object]
