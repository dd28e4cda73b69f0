"""The normal equations of a cameras-and-placements least-squares problem, and their Schur complement.

Each observation (one camera seeing one marker of one wand placement) gives two residual rows; their
Jacobian has a camera part (K columns: the camera's parameters carried) and a placement part (5
columns: A and the wand direction). The normal equations ``J^T W J delta = -J^T W r`` are then

    [ U    W_ ] [dc]   [gc]        U  (C, K, K)  block-diagonal, one block per camera
    [ W_^T V  ] [dp] = [gp]        V  (P, 5, 5)  block-diagonal, one block per placement
                                   W_ (B, K, 5)  one block per (placement, camera) pair seen

and the placements are eliminated by the Schur complement ``S = U - W_ V^-1 W_^T``, a dense
(C K)-square system.

Observations are sorted by placement, then camera, and processed in chunks of whole placements small
enough for a chunk's arrays to stay in the processor's cache: the Jacobians of one chunk are summed
into U, V, W_ and the gradients as soon as they are computed, and never held for the whole problem.
A block's rows (two per marker slot, zero for a marker not seen) make one small matrix: its W_ and
its share of V are one batched product over the chunk's blocks, V summed over each placement's
blocks (``np.add.reduceat``); U and the camera gradient are one BLAS product per camera on the
chunk's blocks gathered by camera.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.errors import CalibrationFailedError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Parameters per placement: A (3), wand direction (2, tangent plane).
N_PLACEMENT_PARAMS = 5
#: Observations per chunk of the linearisation: its arrays (up to a MB each) stay in cache, and each of its
#: numpy calls does enough work to pay for its call (in two threads, the interpreter lock is held while numpy
#: dispatches a call: 4096 left mocap16's evaluations 10 % slower, 20 % at 64 cameras). The chunks of a problem
#: are of equal size near it: up to 1.5x of it is one chunk (a live buffer's 5,700 observations: one
#: evaluation 30 % faster than in two).
CHUNK_OBSERVATIONS = 8192
#: Placements per Schur chunk at most: small enough that a chunk's placements share most of their
#: cameras once sorted by which cameras see them, large enough for one BLAS product to pay.
SCHUR_PLACEMENTS = 128
#: A Schur chunk's dense product may cost at most this many times what its placements' own blocks do,
#: plus SCHUR_OVERHEAD (in the same units: placements times cameras squared) for what a chunk costs of itself
#: (a dozen numpy calls, about as long as 10,000 such units of product): a sparse rig's chunks no smaller
#: than pays. A 64-camera lens test's Schur complement on 1,500 placements (286 -> 58 chunks): 90 -> 70 ms;
#: on all 50,000 placements (2,605 -> 849 chunks) as before; mocap16's chunks are full ones either way.
SCHUR_WASTE = 3.0
SCHUR_OVERHEAD = 10_000


@dataclass(frozen=True, eq=False)
class ObservationChunk:
    """Consecutive observations of whole placements, and where their sums go.

    A chunk's observations are laid out in slots, K per block (one per marker, K the wand's markers;
    a marker not seen leaves its slot empty), so that a block's rows are one (2K, .) matrix.

    Attributes:
        first, stop: the chunk's observations ``first:stop``.
        slot: (n,) each observation's slot, ``K * (block - first_block) + point``.
        full: whether every slot is taken (``slot`` is then 0..n-1).
        first_placement: its first placement (its placements are consecutive).
        placement_starts: (p,) each placement's first block, relative to ``first_block``.
        first_block, n_blocks: its blocks (consecutive).
        by_camera: (b,) its blocks (relative to ``first_block``) ordered by camera.
        camera_bounds: (u + 1,) where each camera's blocks begin and end in ``by_camera``.
        cameras: (u,) the cameras of those runs.
    """

    first: int
    stop: int
    slot: IntArray
    full: bool
    first_placement: int
    placement_starts: IntArray
    first_block: int
    n_blocks: int
    by_camera: IntArray
    camera_bounds: IntArray
    cameras: IntArray


@dataclass(frozen=True, eq=False)
class SchurChunk:
    """Placements accumulated into the Schur complement together, and the cameras they are seen by.

    Attributes:
        placements: (n,) the chunk's placements.
        blocks: (b,) their blocks.
        local_placement: (b,) each block's placement, as an index into ``placements``.
        local_camera: (b,) each block's camera, as an index into ``cameras``.
        cameras: (u,) the cameras seeing them, ascending.
    """

    placements: IntArray
    blocks: IntArray
    local_placement: IntArray
    local_camera: IntArray
    cameras: IntArray


@dataclass(frozen=True, eq=False)
class BlockLayout:
    """Index structure of the normal equations, computed once per adjustment.

    A block is one (placement, camera) pair seen; blocks are numbered in observation order.

    Attributes:
        n_cameras, n_placements: sizes.
        n_points: markers per placement (K).
        width: camera parameters carried per camera (K; 0: placements only).
        block_camera: (B,) each block's camera.
        block_placement: (B,) each block's placement (non-decreasing).
        placement_first_block: (P,) each placement's first block.
        chunks: the observations in cache-sized chunks of whole placements.
        schur_chunks: placements with similar cameras, for S = U - Z Z^T.
    """

    n_cameras: int
    n_placements: int
    n_points: int
    width: int
    block_camera: IntArray
    block_placement: IntArray
    placement_first_block: IntArray
    chunks: tuple[ObservationChunk, ...]
    schur_chunks: tuple[SchurChunk, ...]


def block_starts(placement: IntArray, camera: IntArray) -> IntArray:
    """(B,) the first observation of each block (one placement seen by one camera) of (M,) observations sorted by
    placement, then camera."""
    if placement.size == 0:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(np.r_[True, (placement[1:] != placement[:-1]) | (camera[1:] != camera[:-1])])


def block_layout(
    camera: IntArray, placement: IntArray, point: IntArray, n_cameras: int, n_placements: int, n_points: int, width: int
) -> BlockLayout:
    """The layout of observations ``(camera, placement, point)`` (M,), sorted by placement then camera.

    Args:
        camera, placement, point: (M,) each observation's camera, placement and marker (< ``n_points``).
        n_cameras, n_placements, n_points: sizes.
        width: camera parameters carried per camera (0: placements only).

    Raises:
        ValueError: the observations are not sorted.
        CalibrationFailedError: a placement has no observation.
    """
    if np.any(np.diff(placement * n_cameras + camera) < 0):
        raise ValueError("observations must be sorted by placement, then camera")
    first_of_block = block_starts(placement, camera)
    new_block = np.zeros(camera.size, dtype=bool)
    new_block[first_of_block] = True
    block_of_obs = np.cumsum(new_block) - 1
    block_camera, block_placement = camera[first_of_block], placement[first_of_block]
    placement_first_obs = np.searchsorted(placement, np.arange(n_placements + 1))
    if np.any(np.diff(placement_first_obs) == 0):
        raise CalibrationFailedError("a placement has no observation")
    placement_first_block = np.searchsorted(block_placement, np.arange(n_placements + 1))
    chunks = []
    first_placement = 0
    # whole placements, equal chunks of about CHUNK_OBSERVATIONS observations (a small problem is one)
    size = camera.size / max(round(camera.size / CHUNK_OBSERVATIONS), 1)
    while first_placement < n_placements:
        limit = placement_first_obs[first_placement] + size
        stop_placement = int(np.searchsorted(placement_first_obs, limit, "right")) - 1
        stop_placement = min(max(stop_placement, first_placement + 1), n_placements)
        first, stop = int(placement_first_obs[first_placement]), int(placement_first_obs[stop_placement])
        b0, b1 = int(placement_first_block[first_placement]), int(placement_first_block[stop_placement])
        slot = n_points * (block_of_obs[first:stop] - b0) + point[first:stop]
        local_camera = block_camera[b0:b1]
        cameras, counts = np.unique(local_camera, return_counts=True)
        chunks.append(
            ObservationChunk(
                first,
                stop,
                slot,
                bool(slot.size == n_points * (b1 - b0)),
                first_placement,
                placement_first_block[first_placement:stop_placement] - b0,
                b0,
                b1 - b0,
                np.argsort(local_camera, kind="stable"),
                np.r_[0, np.cumsum(counts)],
                cameras,
            )
        )
        first_placement = stop_placement
    schur = _schur_chunks(block_camera, block_placement, n_cameras, n_placements) if width else ()
    return BlockLayout(
        n_cameras,
        n_placements,
        n_points,
        width,
        block_camera,
        block_placement,
        placement_first_block[:-1],
        tuple(chunks),
        schur,
    )


def _schur_chunks(
    block_camera: IntArray, block_placement: IntArray, n_cameras: int, n_placements: int
) -> tuple[SchurChunk, ...]:
    """Placements sorted by the set of cameras seeing them (lexicographically), cut into chunks.

    A chunk's dense product costs its placements times the square of the cameras its placements are
    seen by together; a chunk is closed before that exceeds SCHUR_WASTE times the sum of its
    placements' own squares and SCHUR_OVERHEAD (large rigs: a ring's placements apart from the next
    ring's) or it holds SCHUR_PLACEMENTS placements.
    """
    seen = np.zeros((n_placements, n_cameras), dtype=bool)
    seen[block_placement, block_camera] = True
    by_rank = np.lexsort(seen[:, ::-1].T)
    masks = [int.from_bytes(row.tobytes(), "little") for row in np.packbits(seen[by_rank], axis=1, bitorder="little")]
    counts = seen.sum(axis=1)[by_rank].tolist()
    chunk_of_rank = np.empty(n_placements, dtype=np.int64)
    chunk, union, size, own = 0, 0, 0, 0
    for position, (mask, count) in enumerate(zip(masks, counts, strict=True)):
        joined = union | mask
        allowed = SCHUR_WASTE * (own + count**2) + SCHUR_OVERHEAD
        if size and (size == SCHUR_PLACEMENTS or (size + 1) * joined.bit_count() ** 2 > allowed):
            chunk, joined, size, own = chunk + 1, mask, 0, 0
        chunk_of_rank[position] = chunk
        union, size, own = joined, size + 1, own + count**2
    rank = np.empty(n_placements, dtype=np.int64)
    rank[by_rank] = np.arange(n_placements)
    first_rank = np.searchsorted(chunk_of_rank, np.arange(chunk + 2))  # each chunk's first rank
    block_chunk = chunk_of_rank[rank[block_placement]]
    order = np.argsort(block_chunk, kind="stable")
    bounds = np.searchsorted(block_chunk[order], np.arange(chunk + 2))
    # each block's camera among its chunk's cameras (ascending): a running count over the cameras seen per chunk
    present = np.zeros((chunk + 1, n_cameras), dtype=bool)
    present[block_chunk, block_camera] = True
    local = np.cumsum(present, axis=1) - 1
    chunks = []
    for i in range(chunk + 1):
        blocks = order[bounds[i] : bounds[i + 1]]
        chunks.append(
            SchurChunk(
                by_rank[first_rank[i] : first_rank[i + 1]],
                blocks,
                rank[block_placement[blocks]] - first_rank[i],
                local[i, block_camera[blocks]],
                np.flatnonzero(present[i]),
            )
        )
    return tuple(chunks)


class NormalEquations(NamedTuple):
    """The blocks of ``J^T W J`` and ``g = -J^T W r`` (see the module docstring).

    Attributes:
        u: (C, K, K) camera blocks (empty without camera parameters).
        v: (P, 5, 5) placement blocks.
        w: (B, K, 5) camera-placement blocks.
        gc: (C, K) camera gradient.
        gp: (P, 5) placement gradient.
    """

    u: FloatArray
    v: FloatArray
    w: FloatArray
    gc: FloatArray
    gp: FloatArray


def empty_normal_equations(layout: BlockLayout, reuse: NormalEquations | None = None) -> NormalEquations:
    """Normal equations of ``layout``'s shapes to accumulate chunks into: zero sums, W to be written block by block.

    Args:
        reuse: normal equations of the same layout no longer needed, whose arrays are taken instead of new
            ones. W is the largest array of an adjustment (520 bytes per block, 80 MB for 10,000 placements
            seen by 16 cameras); a fresh one costs the system's first touch of every page, as much time as
            summing the blocks into it.
    """
    k, c, p = layout.width, layout.n_cameras, layout.n_placements
    if reuse is None:
        return NormalEquations(
            np.zeros((c, k, k)),
            np.zeros((p, N_PLACEMENT_PARAMS, N_PLACEMENT_PARAMS)),
            np.empty((layout.block_camera.size if k else 0, k, N_PLACEMENT_PARAMS)),
            np.zeros((c, k)),
            np.zeros((p, N_PLACEMENT_PARAMS)),
        )
    for sums in (reuse.u, reuse.v, reuse.gc, reuse.gp):
        sums.fill(0.0)
    return reuse


def accumulate(
    normal: NormalEquations,
    layout: BlockLayout,
    chunk: ObservationChunk,
    jc: FloatArray | None,
    jp: FloatArray,
    weights: FloatArray | None,
) -> None:
    """Add one chunk's rows to ``normal`` (in place; its blocks of W are written, not added to).

    Args:
        normal: the sums so far.
        layout: the problem's layout; ``chunk`` one of its chunks.
        jc: (n, 2, K + 1) the chunk's camera Jacobians, the residuals as last column (None: placements only).
        jp: (n, 2, 5 + 1) their placement Jacobians, the residuals as last column.
        weights: (n,) IRLS weights (None: all 1).
    """
    if weights is not None:
        root = np.sqrt(weights)[:, None, None]
        jp = jp * root
        jc = None if jc is None else jc * root
    rows = 2 * layout.n_points  # of a block
    # Placements: jp^T [jp | r] per block (V's and gp's rows), summed over each placement's blocks. (Not the
    # whole [jp | r]^T [jp | r]: numpy hands a product of an array with its own transpose to BLAS's syrk, matrix by
    # matrix, four times slower on these 6 x 6 blocks than its own loop.)
    jp_blocks = _by_block(jp, chunk, layout.n_points)
    per_block = jp_blocks[:, :, :N_PLACEMENT_PARAMS].transpose(0, 2, 1) @ jp_blocks
    summed = np.add.reduceat(per_block, chunk.placement_starts, axis=0)
    placements = slice(chunk.first_placement, chunk.first_placement + chunk.placement_starts.size)
    normal.v[placements] += summed[:, :, :N_PLACEMENT_PARAMS]
    normal.gp[placements] -= summed[:, :, N_PLACEMENT_PARAMS]
    if jc is None:
        return
    width = jc.shape[2] - 1
    jc_blocks = _by_block(jc, chunk, layout.n_points)
    # Blocks: jc^T jp over each block's rows (a block's observations are all in one chunk).
    blocks = slice(chunk.first_block, chunk.first_block + chunk.n_blocks)
    normal.w[blocks] = (jc_blocks[:, :, :width].transpose(0, 2, 1) @ jp_blocks)[:, :, :N_PLACEMENT_PARAMS]
    # Cameras: [jc | r]^T [jc | r] over each camera's rows, one BLAS product per camera.
    by_camera = jc_blocks[chunk.by_camera].reshape(-1, width + 1)
    for camera, first, stop in zip(chunk.cameras, chunk.camera_bounds[:-1], chunk.camera_bounds[1:], strict=True):
        part = by_camera[rows * first : rows * stop]
        product = part.T @ part
        normal.u[camera] += product[:width, :width]
        normal.gc[camera] -= product[:width, width]


def _by_block(rows: FloatArray, chunk: ObservationChunk, n_points: int) -> FloatArray:
    """(b, 2 n_points, k) a chunk's (n, 2, k) rows, one matrix per block (rows of unseen markers zero)."""
    if not chunk.full:
        slots = np.zeros((chunk.n_blocks * n_points, *rows.shape[1:]))
        slots[chunk.slot] = rows
        rows = slots
    return rows.reshape(chunk.n_blocks, 2 * n_points, rows.shape[2])


#: A block whose condition number may exceed this (the bound (|C|_F |C^-1|_F)^2 of its Cholesky factor C) is
#: inverted by LU and factored again (:func:`_inverse_and_root`), as before the forward substitution: placements
#: far from narrow cameras (up to 3e12 there). Elsewhere blocks stay below it: mocap16's up to 1.7e8, the live
#: buffer's 1.6e7 (millimetres beside radians).
ILL_CONDITIONED = 1e9


def _inverse_and_root(v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """V^-1 and L^T, contiguous, for a factor L with L L^T = V^-1, of (P, 5, 5) symmetric positive definite blocks.

    With V = C C^T (Cholesky), L^T = C^-1 by forward substitution, all blocks at once, and V^-1 = (C^-1)^T C^-1
    (numpy's batched inverse makes a LAPACK call per block: 10,000 blocks 11.7 -> 6.9 ms). Ill-conditioned blocks
    (:data:`ILL_CONDITIONED`) and blocks only numerically positive definite take that inverse, L its Cholesky
    factor, else its symmetric square root.
    """
    try:
        lower = np.linalg.cholesky(v)
    except np.linalg.LinAlgError:
        return _inverse_and_root_by_lu(v)
    n = lower.shape[-1]
    inverse, inverse_t = np.zeros_like(lower), np.zeros_like(lower)  # C^-1 and its transpose, both contiguous
    diagonal = 1.0 / np.einsum("pii->pi", lower)
    for i in range(n):
        inverse[:, i, i] = inverse_t[:, i, i] = diagonal[:, i]
        for j in range(i):
            total = lower[:, i, j] * inverse[:, j, j]
            for k in range(j + 1, i):
                total = total + lower[:, i, k] * inverse[:, k, j]
            inverse[:, i, j] = inverse_t[:, j, i] = -total * diagonal[:, i]
    v_inv = inverse_t @ inverse
    bound = np.einsum("pij,pij->p", lower, lower) * np.einsum("pij,pij->p", inverse, inverse)  # (|C|_F |C^-1|_F)^2
    ill = np.flatnonzero(~(bound <= ILL_CONDITIONED))
    if ill.size:
        v_inv[ill], inverse[ill] = _inverse_and_root_by_lu(v[ill])
    return v_inv, inverse


def _inverse_and_root_by_lu(v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`_inverse_and_root` by numpy's batched inverse: L the Cholesky factor of V^-1, else (numerically
    semi-definite) its symmetric square root."""
    v_inv = np.linalg.inv(v)
    v_inv = 0.5 * (v_inv + v_inv.transpose(0, 2, 1))
    try:
        root = np.asarray(np.linalg.cholesky(v_inv), dtype=np.float64)
    except np.linalg.LinAlgError:  # numerically semi-definite: symmetric square root
        values, vectors = np.linalg.eigh(v_inv)
        root = vectors * np.sqrt(np.clip(values, 0.0, None))[:, None, :]
    return v_inv, np.ascontiguousarray(root.transpose(0, 2, 1))


def reduced_system(normal: NormalEquations, layout: BlockLayout) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Schur complement S = U - W V^-1 W^T (dense, KC square), its right-hand side and V^-1.

    With L L^T = V_j^-1 and Z_b = W_b L_j, S = U - Z Z^T where Z is the (KC x 5P) matrix of the
    blocks Z_b. Per chunk of placements, over the cameras that chunk's placements are seen by (so
    cameras that share no placement cost nothing): the chunk's W^T blocks laid out densely, one
    product with each placement's L^T, and one BLAS product Z Z^T.
    """
    u, v, w, gc, gp = normal
    n_cameras, width = layout.n_cameras, layout.width
    v_inv, root_t = _inverse_and_root(v)
    projected = (root_t @ gp[..., None])[..., 0]  # (P, 5): L_j^T gp_j
    by_block = np.zeros((n_cameras, n_cameras, width, width))  # camera-block layout: whole blocks per update
    by_block[np.arange(n_cameras), np.arange(n_cameras)] = u
    rhs = gc.copy()  # rhs = gc - sum_b W_b V_j^-1 gp_j = gc - sum_b Z_b (L_j^T gp_j)
    for chunk in layout.schur_chunks:
        n, u_local = chunk.placements.size, chunk.cameras.size
        dense = np.zeros((n * u_local, width, N_PLACEMENT_PARAMS))  # (placement, camera) major
        dense[chunk.local_placement * u_local + chunk.local_camera] = w[chunk.blocks]
        # per placement its W^T, the cameras side by side: (n, 5, u K)
        w_t = dense.reshape(n, u_local * width, N_PLACEMENT_PARAMS).transpose(0, 2, 1)
        z_t = root_t[chunk.placements] @ w_t  # (n, 5, u K)
        flat = z_t.reshape(n * N_PLACEMENT_PARAMS, u_local * width)  # rows (placement, j), columns (camera, k)
        product = (flat.T @ flat).reshape(u_local, width, u_local, width).transpose(0, 2, 1, 3)
        by_block[chunk.cameras[:, None], chunk.cameras[None, :]] -= product
        rhs[chunk.cameras] -= (flat.T @ projected[chunk.placements].reshape(-1)).reshape(u_local, width)
    size = n_cameras * width
    return by_block.transpose(0, 2, 1, 3).reshape(size, size), rhs.reshape(size), v_inv


def back_substitute(delta_c: FloatArray, v_inv: FloatArray, normal: NormalEquations, layout: BlockLayout) -> FloatArray:
    """(P, 5) the placements' step for the cameras' step ``delta_c`` (C, K): V^-1 (gp - W^T delta_c)."""
    # (B, 5), one small product per block (einsum's loop took 11 ms for mocap16's 150,000 blocks, this 6.5)
    wt_dc = (delta_c[layout.block_camera][:, None, :] @ normal.w)[:, 0, :]
    per_placement = np.add.reduceat(wt_dc, layout.placement_first_block, axis=0)
    return (v_inv @ (normal.gp - per_placement)[..., None])[..., 0]


def scaling(blocks: FloatArray) -> FloatArray:
    """(..., n) the Levenberg-Marquardt scaling D of (..., n, n) diagonal blocks: their diagonal, floored."""
    diag = np.einsum("...ii->...i", blocks)
    return np.maximum(diag, 1e-9 * max(float(np.max(diag, initial=0.0)), 1e-12))


def damp(blocks: FloatArray, lam: float) -> FloatArray:
    """The blocks plus lam D (and a trace of D, so that zero rows stay solvable)."""
    scale = scaling(blocks)
    damped = blocks.copy()
    idx = np.arange(blocks.shape[-1])
    damped[..., idx, idx] += lam * scale + 1e-12 * float(np.min(scale, initial=1.0))
    return damped


def damped(normal: NormalEquations, lam: float) -> NormalEquations:
    """The normal equations with U and V damped by ``lam`` (W and the gradients shared)."""
    u = damp(normal.u, lam) if normal.u.size else normal.u
    return NormalEquations(u, damp(normal.v, lam), normal.w, normal.gc, normal.gp)


def undamped(normal: NormalEquations) -> NormalEquations:
    """The normal equations as they are but for V's trace of D (zero rows stay solvable): Gauss-Newton's
    system, and the one the covariance comes from."""
    return normal._replace(v=damp(normal.v, 0.0))


def jacobi_scale(s: FloatArray) -> FloatArray:
    """(N,) 1 / sqrt(diag(s)) (1 where the diagonal is not positive): ``s`` scaled by it on both sides has a unit
    diagonal. A camera's parameters span many orders of magnitude (a focal of 25,000 px beside rotations in
    radians); solved or inverted unscaled, their small directions drown in the large ones' rounding. (Not
    :func:`scaling`, the damping's diagonal: its floor, right for damping, would leave those directions
    unscaled.)"""
    diagonal = np.diag(s)
    return np.asarray(np.where(diagonal > 0, 1.0 / np.sqrt(np.where(diagonal > 0, diagonal, 1.0)), 1.0))


def solve_free(s: FloatArray, rhs: FloatArray, free: NDArray[np.bool_]) -> FloatArray:
    """The solution of ``s x = rhs`` over the ``free`` unknowns (the others 0), Jacobi-scaled (:func:`jacobi_scale`):
    Cholesky, else least squares."""
    delta = np.zeros_like(rhs)
    if not free.any():
        return delta
    sub = s[np.ix_(free, free)]
    scale = jacobi_scale(sub)
    scaled = sub * scale[:, None] * scale[None, :]
    try:
        # numpy's LAPACK throughout: scipy's is a second BLAS thread pool, and the two contend
        np.linalg.cholesky(scaled)  # positive definite, else least squares
        delta[free] = scale * np.linalg.solve(scaled, scale * rhs[free])
    except np.linalg.LinAlgError:
        delta[free] = scale * np.linalg.lstsq(scaled, scale * rhs[free], rcond=None)[0]
    return delta


#: A Jacobi-scaled matrix whose condition number is below this is inverted directly (its pseudo-inverse, which
#: drops only eigenvalues below 1e-15 of the largest, is the inverse then).
DIRECT_INVERSE_CONDITION = 1e12


def _direct_inverse(scaled: FloatArray) -> FloatArray | None:
    """The inverse of a Jacobi-scaled symmetric matrix, or None unless it is positive definite and its condition
    number (at most ``trace(s) trace(s^-1)``) is below DIRECT_INVERSE_CONDITION."""
    try:
        np.linalg.cholesky(scaled)  # positive definite
        inverse = np.asarray(np.linalg.inv(scaled), dtype=np.float64)
    except np.linalg.LinAlgError:
        return None
    diagonal = np.diag(inverse)  # (positive, the inverse's rounding small: else it is not the inverse)
    if not (np.all(diagonal > 0) and np.trace(scaled) * np.sum(diagonal) < DIRECT_INVERSE_CONDITION):
        return None
    return 0.5 * (inverse + inverse.T)


def scaled_inverse(s: FloatArray) -> FloatArray:
    """The (pseudo-)inverse of a symmetric positive semi-definite ``s``, Jacobi-scaled (:func:`jacobi_scale`):
    directions the data leave undetermined get no variance rather than the rounding of others'.

    A well-conditioned one (positive definite, its condition number bounded by ``trace(s) trace(s^-1)`` below
    DIRECT_INVERSE_CONDITION) is inverted directly, several times faster than the eigendecomposition the
    pseudo-inverse takes (832 parameters, 64 cameras': 37 against 70 ms here).
    """
    scale = jacobi_scale(s)
    scaled = s * scale[:, None] * scale[None, :]
    inverse = _direct_inverse(scaled)
    if inverse is None:
        inverse = np.asarray(np.linalg.pinv(scaled, hermitian=True), dtype=np.float64)
    return np.asarray(inverse * scale[:, None] * scale[None, :])
