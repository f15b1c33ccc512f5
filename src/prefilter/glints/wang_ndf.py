"""Per-tile footprint pyramids over Wang tiles: bake, compression, queries, sampling (sec. 5.5).

The tiles, their implicit tiling and the direct P-NDF across tiles are in
:mod:`prefilter.glints.wang`; this module precomputes and queries footprint NDFs over the tiled
plane without assembling the texels under the footprint.

**Per-tile pyramids** (:func:`bake_tiles`, design and measurements in docs/glints-wang.md). The
P-NDF is linear in the texel weights: ``D_p = sum_tiles sum_{i in tile} w_i N_i / sum_all w_i``,
so a footprint's NDF is the sum over the tiles it touches of that tile's *contribution*, an image
carrying the tile's share of the footprint mass. For each of the 16 tiles the contribution is
precomputed for footprint centres on and around the tile (a margin of ``TRUNCATION`` footprint
stds: footprints centred on neighbouring tiles reaching in), on the footprint pyramid of
``pyramid.py`` (level 0 by ``pndf_image`` with the other texels' elements moved out of the NDF
square, so they count in the normalisation only; upper levels by exact Gaussian filtering).
The border texels whose Jacobian depends on the neighbour tile beyond its edge colour (the
corner squares, :func:`dependent_texels`) are left out and added exactly at query time, or, in
compressed bakes, from 16 more pyramids of them per vertex configuration (:func:`vertex_tiles`:
the vertex tiles of a valid tiling partition its dependent texels).
Queries between centres/levels use Gaussian resampling (``pyramid.resample_weights``' scheme) per
tile, summed over the tiles under the truncation window; smaller footprints use the direct P-NDF;
footprints with ``sigma_p >= wide_tiles * T`` the tile-type shares: the footprint's weights
summed per tile type, times quadratics of each texel's place in its tile
(:func:`type_moments`), weighting each tile's moment images (:func:`tile_moment_images`, the
texels' NDFs projected on those quadratics); from ``uniform_tiles * T`` the tile-independent NDF
of the expected tiling (every tile equally likely), the position average of the footprint NDF
at any size.
Optionally CP-compressed per (tile, level, angular block) (:func:`compress_tiles`). Storage: 16
tiles' pyramids, independent of the synthesised area. Sampling: a tile contribution by mass, a
pixel by its CDF, uniform in the pixel.

On-disk format: :mod:`prefilter.glints.wang_store` (``save_tiles`` / ``load_tiles``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from prefilter.jit import kernel_array, njit_parallel, njit_serial, prange, serial
from prefilter.validation import as_float_array, as_positive_int, as_rng, broadcast_batch
from prefilter.errors import PrefilterError
from prefilter.glints.pndf import (DEFAULT_ROUGHNESS, SIGMA_H, TRUNCATION,
                                   as_intrinsic_roughness, as_sigma_p, as_support,
                                   element_covariance, element_density, element_node,
                                   element_nodes, element_split, normal_cdf, pixel_edges,
                                   pndf_image, principal_axis, splat_element)
from prefilter.glints._qkernels import pixel_taps
from prefilter.glints._simd import exp_neg
from prefilter.glints.brdf import _ANGULAR_CUT, _exponents, _row_gaussians
from prefilter.glints.wang_query import (TilePack, empty_pack, gauss_row, pack_float,
                                         pack_point, segment_moments, tile_taps)
from prefilter.glints.pyramid import next_level
from prefilter.glints.wang import (WangTiles, as_center, as_one_sigma_p, assemble, edge_colours,
                                   edge_type, hash_bits, implicit_type, is_valid_tiling,
                                   pndf_image_implicit,
                                   tile_index, tile_window)


def tile_elements(wt: WangTiles) -> tuple[np.ndarray, np.ndarray]:
    """Per-tile elements ``s (16, T, T, 2)``, ``J (16, T, T, 2, 2)`` (as ``pndf.elements``).

    The central differences at a tile's border need the neighbour's texels, which depend on the
    edge colour only away from the corner squares (module docstring). Each side is padded with
    the mean of the adjacent rows of the 8 tiles that can sit there (the expected neighbour, so
    the Jacobian is its expectation over tilings); exact except in the corner squares.
    """
    T = wt.size
    S = wt.tiles[..., :2]
    n, s, w, e = edge_colours(np.arange(16))
    pad = np.zeros((16, T + 2, T + 2, 2))
    pad[:, 1:-1, 1:-1] = S
    for t in range(16):
        pad[t, 0, 1:-1] = S[s == n[t], T - 1].mean(axis=0)  # bottom rows of the tiles above
        pad[t, -1, 1:-1] = S[n == s[t], 0].mean(axis=0)
        pad[t, 1:-1, 0] = S[e == w[t], :, T - 1].mean(axis=0)
        pad[t, 1:-1, -1] = S[w == e[t], :, 0].mean(axis=0)
    J = np.empty((16, T, T, 2, 2))
    J[..., :, 0] = 0.5 * (pad[:, 1:-1, 2:] - pad[:, 1:-1, :-2])
    J[..., :, 1] = 0.5 * (pad[:, 2:, 1:-1] - pad[:, :-2, 1:-1])
    return np.ascontiguousarray(S), J


def dependent_texels(wt: WangTiles) -> np.ndarray:
    """``(T, T)`` mask of the border texels whose Jacobian depends on which neighbour tile sits
    across the edge (not only on the edge colour): the ends of the edges, where the neighbour's
    corner square is. The per-tile pyramids leave them out; queries add them exactly."""
    T = wt.size
    S = wt.tiles[..., :2]
    n, s, w, e = edge_colours(np.arange(16))

    def varies(rows):  # (8, T, 2) candidate neighbour rows -> (T,) differ anywhere
        return np.any(np.abs(rows - rows[:1]) > 1e-12, axis=(0, 2))

    dep = np.zeros((T, T), bool)
    for c in (0, 1):
        dep[0] |= varies(S[s == c, T - 1])
        dep[-1] |= varies(S[n == c, 0])
        dep[:, 0] |= varies(S[e == c, :, T - 1])
        dep[:, -1] |= varies(S[w == c, :, 0])
    return dep


#: Elements moved here contribute nothing to an NDF image (``support <= 1``) but keep their
#: footprint weight in its normalisation.
_AWAY = 9.0


@dataclass(frozen=True)
class TiledNDF:
    """Per-tile footprint pyramids of a :class:`WangTiles` set (:func:`bake_tiles`).

    ``images[l]`` is ``(16, n_l, n_l, R, R)`` float32: tile ``t``'s contribution for footprints
    of std ``sigma0 2^l`` centred at ``((k0[l] + a) stride_l + 0.5, (k0[l] + b) stride_l + 0.5)``
    relative to the tile's corner (index ``[t, b, a]``); contributions of centres outside are 0.
    Compressed (``block > 0``): ``images[l]`` is the CP triple ``A, Bf (16, nb^2, rank, B)``,
    ``C (16, n_l, n_l, nb^2, rank)`` float32 of the ``B x B`` angular blocks (group ``g = bi nb
    + bj``): pixel ``(bi B + i, bj B + j)`` of image ``[t, b, a]`` is
    ``sum_r A[t, g, r, i] Bf[t, g, r, j] C[t, b, a, g, r]`` (glints paper eq. 5);
    ``cp_error[l]``: relative L2 error of level ``l``'s stored images.
    ``tile_means (16, R, R)``: each tile's ``sigma_p -> inf`` NDF (its texels with equal
    weights); ``mean (R, R)``: their average, the tile-independent NDF (expected tiling).
    """

    wang: WangTiles
    images: tuple
    k0: tuple
    mean: np.ndarray
    stride0: int
    sigma0: float
    resolution: int
    support: float
    intrinsic_roughness: float
    wide_sigma: float
    dependent: np.ndarray  # (n_dep, 2) (row, col) of dependent_texels(wang)
    tile_means: np.ndarray | None = None  # (16, R, R) each tile's sigma_p -> inf NDF
    uniform_sigma: float = math.inf
    block: int = 0
    cp_error: tuple = ()
    #: a ``wang_store`` version-2 file's levels packed from their integer codes
    #: (:func:`prefilter.glints.wang_query.pack_codes`); ``images`` is then decoded from it on
    #: first use
    packed: TilePack | None = None
    #: compressed bakes: the dependent texels' pyramids on vertex-centred tiles, one per vertex
    #: configuration (:func:`vertex_tiles`; levels and layout as ``images``, centres from
    #: ``vertex_k0[l]``: the crops around the vertex its dependent texels reach), their CP
    #: errors and, loaded from a file, their pack
    vertex_images: tuple = ()
    vertex_cp_error: tuple = ()
    vertex_packed: TilePack | None = None
    vertex_k0: tuple = ()
    #: compressed bakes: the same pyramids (tiles' and vertex) of the NDF images averaged over
    #: ``p x p`` pixels (``bake_tiles(angular_pool=p)``; ``resolution`` ``R / p``, same
    #: centres), which the range queries read for wide rectangles; ``None``: not made
    coarse: "TiledNDF | None" = None
    #: summed-area tables ``(R + 1, R + 1, 16, 5)`` float32 of the tiles' in-tile moment
    #: images (:func:`moment_tables` of :func:`tile_moment_images`), which the tile-type
    #: shares regime weights by the footprint's moments over each tile (:func:`type_moments`);
    #: ``None``: the shares alone
    moment_sat: np.ndarray | None = None

    @property
    def n_levels(self) -> int:
        return len(self.images)

    @property
    def pack(self) -> TilePack:
        """The compressed pyramids in the query kernels' layout (:mod:`prefilter.glints.
        wang_query`): the integer codes when loaded from a version-2 file, else from the
        float32 CP triples; built once per instance. Uncompressed: an empty pack."""
        if self.packed is not None:
            return self.packed
        hit = self.__dict__.get("_pack")
        if hit is None:
            hit = pack_float(self.images) if self.block else empty_pack(self.n_levels)
            object.__setattr__(self, "_pack", hit)
        return hit

    @property
    def means_px(self) -> np.ndarray:
        """``tile_means`` position-major, ``(R, R, 16)`` float64 (the point kernels' tile-type
        shares read a pixel's 16 values together); built once per instance."""
        hit = self.__dict__.get("_means_px")
        if hit is None:
            hit = np.ascontiguousarray(np.asarray(self.tile_means, np.float64).transpose(1, 2, 0))
            object.__setattr__(self, "_means_px", hit)
        return hit

    @property
    def vertex_pack(self) -> TilePack | None:
        """:attr:`pack` of the vertex pyramids (``None`` without them)."""
        if self.vertex_packed is not None:
            return self.vertex_packed
        if not self.vertex_images:
            return None
        hit = self.__dict__.get("_vpack")
        if hit is None:
            hit = pack_float(self.vertex_images)
            object.__setattr__(self, "_vpack", hit)
        return hit

    def vertex_crop(self, level: int) -> int:
        """Centres per axis of the vertex pyramids at ``level`` (0 without them)."""
        vp = self.vertex_pack
        return 0 if vp is None else int(vp.crops[level])

    def stride(self, level: int) -> int:
        return self.stride0 << level

    def sigma(self, level: int) -> float:
        return self.sigma0 * 2.0**level

    @property
    def nbytes(self) -> int:
        """Bytes in memory of what the batched queries (:func:`ndf_points`, the renderer) read:
        tiles, per-tile pyramids (float32 images, or the packed CP factors of :attr:`pack`:
        the integer codes of a version-2 file, the float32 factors otherwise), the mean and
        per-tile images (and their position-major float64 copy, :attr:`means_px`), the moment
        tables, and the range queries' summed-area tables of those images once a range query
        built them (:func:`prefilter.glints.wang_range.summed_tables`; no per-area data). The
        float32 CP triples of a loaded file, decoded
        on first use by the per-footprint NumPy paths (:func:`ndf`, :func:`contributions`,
        :func:`sample`), are not counted."""
        if self.block:
            levels = self._packs_nbytes()
        else:
            levels = sum(a.nbytes for a in self.images)
        msat = sum(0 if w is None or w.moment_sat is None else w.moment_sat.nbytes
                   for w in (self, self.coarse))
        sat = self.__dict__.get("_sat")
        return int(self.wang.nbytes + levels + self.mean.nbytes + self.tile_means.nbytes
                   + self.tile_means.size * 8 + msat + (0 if sat is None else sat.nbytes))

    def _packs_nbytes(self) -> int:
        """Bytes of the packed tile and vertex pyramids, and of the coarse ones'."""
        n = self.pack.nbytes + (0 if self.vertex_pack is None else self.vertex_pack.nbytes)
        return n + (0 if self.coarse is None else self.coarse._packs_nbytes())

    def crop(self, level: int) -> int:
        """Footprint centres per axis stored for each tile at ``level``."""
        if self.packed is not None:
            return int(self.packed.crops[level])
        a = self.images[level]
        return int((a if isinstance(a, np.ndarray) else a[2]).shape[1])

    @property
    def min_sigma(self) -> float:
        """Footprints below this std use the direct P-NDF (no pyramid level resamples them)."""
        a = _Q_MIN * self.stride0 / self.sigma0
        return self.sigma0 / math.sqrt(1.0 - a * a) if a < 1.0 else math.inf


def _margin(sigma: float) -> float:
    # texel centres within TRUNCATION total stds of a footprint centre carry weight
    return TRUNCATION * math.sqrt(sigma * sigma + SIGMA_H**2) + 1.0


def bake_tiles(wt: WangTiles, *, ndf_res: int = 64, support: float = 0.5,
               intrinsic_roughness: float = DEFAULT_ROUGHNESS, stride0: int | None = None,
               wide_tiles: float = 0.5, uniform_tiles: float = 8.0, rank: int | None = None,
               block: int = 8, n_iter_max: int = 100, seed: int = 0, angular_pool: int = 4,
               progress: bool = False) -> TiledNDF:
    """Per-tile footprint pyramids (glints paper sec. 5.5, Fig. 12), float32, uncompressed or
    CP-compressed (``rank``).

    Parameters
    ----------
    wt : the 16 tiles (:func:`synthesize`).
    ndf_res, support, intrinsic_roughness : NDF images ``R x R`` over ``[-support, support]^2``.
    stride0 : level-0 centre stride in texels (``sigma0 = stride0``); default ``T // 8``.
    wide_tiles : footprints with ``sigma_p >= wide_tiles * T`` use the tile-type shares and
        in-tile moments (:func:`type_moments`, :attr:`TiledNDF.moment_sat`); the pyramid has
        the levels that resample some ``sigma_p`` below it (from ``sigma_l / sqrt(1 - 0.6^2)``
        up: ``sigma_l < 0.8 wide_tiles T``).
    uniform_tiles : footprints with ``sigma_p >= uniform_tiles * T`` use the tile-independent
        NDF (expected tiling, O(1)); ``inf`` never.
    rank, block : if ``rank`` is given, each (tile, level) is compressed like a bake cell
        (``cp.nn_cp_batch`` of one ``(B, B, n_l^2)`` tensor per angular block position, all
        groups at ``rank``; all-zero groups dropped); ``n_iter_max``, ``seed``: of the fits.
        The same factors as :func:`compress_tiles` of the uncompressed result, with a lower
        memory peak: each level is compressed and dropped once the next one is filtered.
    angular_pool : with ``rank``, also the pyramids of the images averaged over ``p x p``
        pixels (``ndf_res / p`` per axis, blocks of ``block``), :attr:`TiledNDF.coarse`: the
        range queries read them for rectangles of at least ``COARSE_MIN`` of their pixels per
        side (fewer angular blocks). Made when ``ndf_res / p`` is a multiple of ``block`` with
        at least 2 x 2 blocks; 0 or 1: never.
    progress : a progress bar per tile (and per compressed level) on stderr.
    """
    T = wt.size
    R = as_positive_int(ndf_res, "ndf_res")
    S = as_support(support)
    sr = as_intrinsic_roughness(intrinsic_roughness)
    st0 = max(1, T // 8) if stride0 is None else as_positive_int(stride0, "stride0")
    wide = float(wide_tiles)
    if not (0.0 < wide <= 4.0):
        raise PrefilterError(f"wide_tiles: expected a footprint std in tiles in (0, 4], got "
                             f"{wide_tiles!r}")
    uniform = float(uniform_tiles)
    if not uniform >= wide:
        raise PrefilterError(f"uniform_tiles: expected a footprint std in tiles >= wide_tiles = "
                             f"{wide}, got {uniform_tiles!r}")
    if rank is not None:  # before the bake, not after minutes of it
        rank = as_positive_int(rank, "rank")
        block = as_positive_int(block, "block")
        n_iter_max = as_positive_int(n_iter_max, "n_iter_max")
        if R % block:
            raise PrefilterError(f"block: expected a divisor of ndf_res {R}, got {block}")
    if (isinstance(angular_pool, bool) or not isinstance(angular_pool, (int, np.integer))
            or angular_pool < 0):
        raise PrefilterError(f"angular_pool: expected an integer >= 0, got {angular_pool!r}")
    pool = int(angular_pool)
    if rank is None or pool < 2 or R % pool or (R // pool) % block or R // pool < 2 * block:
        pool = 0
    # level l resamples footprints from sigma_l / sqrt(1 - _Q_MIN^2) up (level_window's rule,
    # the stride equal to the std): only the levels that serve some sigma_p below wide * T
    L = 1
    while st0 * 2.0**L / math.sqrt(1.0 - _Q_MIN**2) < wide * T:
        L += 1
    sig = [float(st0 << lv) for lv in range(L)]
    k0 = [math.floor((-_margin(sg) - 0.5) / (st0 << lv)) for lv, sg in enumerate(sig)]
    k1 = [math.ceil((T + _margin(sg) - 0.5) / (st0 << lv)) for lv, sg in enumerate(sig)]
    s_el, J_el = tile_elements(wt)
    dep = dependent_texels(wt)
    kw = dict(L=L, st0=st0, k0=k0, k1=k1, R=R, S=S, sr=sr, rank=rank, block=block,
              n_iter_max=n_iter_max, seed=seed, progress=progress, pool=pool)
    done, errs, cdone, cerrs = _pyramid_levels(s_el, J_el, np.broadcast_to(~dep, (16, T, T)),
                                 desc="tile pyramids", **kw)
    # sigma_p -> inf limit on the tile alone: each texel once, N(n_i, sr^2 + sh^2 J J^T)
    tile_means = np.stack([pndf_image(None, (0.5 * T, 0.5 * T), 1e5, R, S, sr,
                                      elements_=(s_el[t], J_el[t])) for t in range(16)])
    vdone, verrs = (), ()
    if rank is not None:
        # the dependent texels, per vertex configuration, on vertex-centred tiles
        vs, vJ, vkeep = vertex_tiles(wt, dep)
        # their crops: the centres within a margin of the texels (the vertex tiles' other
        # centres have no contribution)
        rows = np.flatnonzero(vkeep.any(axis=(0, 2)) | vkeep.any(axis=(0, 1)))
        vk0 = [math.floor((rows[0] - _margin(sg) - 0.5) / (st0 << lv))
               for lv, sg in enumerate(sig)]
        vk1 = [math.ceil((rows[-1] + 1 + _margin(sg) - 0.5) / (st0 << lv))
               for lv, sg in enumerate(sig)]
        vdone, verrs, vcdone, vcerrs = _pyramid_levels(vs, vJ, vkeep, desc="vertex pyramids",
                                                       **dict(kw, k0=vk0, k1=vk1))
    msat = moment_tables(tile_moment_images(wt, R, S, sr))
    wn = TiledNDF(wt, done, tuple(k0), tile_means.mean(axis=0), st0, float(st0), R, S,
                  sr, wide * T, np.argwhere(dep), tile_means, uniform * T, moment_sat=msat)
    if rank is None:
        return wn
    wn = replace(wn, block=block, cp_error=errs, vertex_images=vdone, vertex_cp_error=verrs,
                 vertex_k0=tuple(vk0))
    if not pool:
        return wn
    tm = tile_means.reshape(16, R // pool, pool, R // pool, pool).mean(axis=(2, 4))
    coarse = replace(wn, images=cdone, resolution=R // pool, tile_means=tm,
                     mean=tm.mean(axis=0), cp_error=cerrs, vertex_images=vcdone,
                     vertex_cp_error=vcerrs, moment_sat=pooled_tables(msat, pool))
    return replace(wn, coarse=coarse)


def _pyramid_levels(s_el, J_el, keep, *, L, st0, k0, k1, R, S, sr, rank, block, n_iter_max,
                    seed, progress, desc, pool=0):
    """The ``L`` pyramid levels of 16 element sets ``s_el (16, T, T, 2)``, ``J_el (16, T, T,
    2, 2)`` of which the texels ``keep (16, T, T)`` contribute (the others count in the
    footprint weights only), centres ``k0[l] .. k1[l]`` per axis: level 0 by ``pndf_image``,
    upper levels by exact Gaussian filtering; with ``rank`` each level compressed and dropped
    once the next is filtered from it (at most two levels' images held), and with ``pool``
    also its images averaged over ``pool x pool`` pixels. Returns the levels and their CP
    errors (empty without ``rank``), and those of the averaged images (empty without
    ``pool``)."""
    T = s_el.shape[1]
    sig0 = float(st0)
    # level-0 element canvas: the tile and every texel a cropped level-0 footprint reaches
    o = st0 * math.ceil((_margin(sig0) + st0) / st0)  # tile corner, on the level-0 grid
    P = o + st0 * math.ceil((T + _margin(sig0) + st0) / st0)

    def crop(lv):
        return np.empty((16, k1[lv] - k0[lv] + 1, k1[lv] - k0[lv] + 1, R, R), np.float32)

    level = crop(0)
    g = (np.arange(k0[0], k1[0] + 1) * st0 + 0.5) + o
    cen = np.stack(np.meshgrid(g, g), axis=-1)
    from tqdm import tqdm

    for t in tqdm(range(16), desc=desc, disable=not progress):
        cs = np.full((P, P, 2), _AWAY)
        cj = np.zeros((P, P, 2, 2))
        cs[o:o + T, o:o + T] = np.where(keep[t][..., None], s_el[t], _AWAY)
        cj[o:o + T, o:o + T] = J_el[t]
        level[t] = pndf_image(None, cen, sig0, R, S, sr, elements_=(cs, cj))
    done, errs, cdone, cerrs = [], [], [], []
    for lv in tqdm(range(1, L + 1), desc="levels", disable=not progress or rank is None):
        nxt = None
        if lv < L:
            nxt = crop(lv)
            for t in range(16):
                nxt[t] = _filter_crop(level[t], k0[lv - 1], k0[lv], k1[lv], sig0 / st0)
        if rank is None:
            done.append(level)
        else:
            n = level.shape[1]
            if pool:
                Rc = R // pool
                pooled = level.reshape(16, n, n, Rc, pool, Rc, pool).mean(axis=(4, 6),
                                                                         dtype=np.float64)
                packed, err = _compress_tensors(_level_tensors(pooled.astype(np.float32),
                                                               block), 16, n, rank, block,
                                                n_iter_max, seed + lv - 1)
                del pooled
                cdone.append(packed)
                cerrs.append(err)
            tensors = _level_tensors(level, block)
            level = None  # the images are freed: the fits need only the tensors
            packed, err = _compress_tensors(tensors, 16, n, rank, block, n_iter_max,
                                            seed + lv - 1)
            del tensors
            done.append(packed)
            errs.append(err)
        level = nxt
    return tuple(done), tuple(errs), tuple(cdone), tuple(cerrs)


def _filter_crop(crop, a0, b0, b1, sigma_over_stride):
    """Level ``l + 1`` images of centres ``b0 .. b1`` (per axis) from the level-``l`` crop
    ``(n, n, R, R)`` of centres ``a0 ..``: the crop zero-padded on a periodic grid wide enough
    that the filter (``pyramid.next_level``, ~7 strides) never wraps, starting at an even
    index so that level-``l`` centre ``2 k`` is level-``l + 1`` centre ``k``. The contributions
    beyond a crop are Gaussian tails (``TRUNCATION`` stds out) and are dropped."""
    n = crop.shape[0]
    pad = math.ceil(4.0 * math.sqrt(3.0) * sigma_over_stride) + 1
    lo = min(a0, 2 * b0) - pad
    lo -= lo % 2
    hi = max(a0 + n - 1, 2 * b1) + pad
    N = hi - lo + 1 + (hi - lo + 1) % 2
    grid = np.zeros((N, N) + crop.shape[2:], np.float32)
    grid[a0 - lo:a0 - lo + n, a0 - lo:a0 - lo + n] = crop
    out = next_level(grid, sigma_over_stride)
    return out[b0 - lo // 2:b1 - lo // 2 + 1, b0 - lo // 2:b1 - lo // 2 + 1]


def compress_tiles(wn: TiledNDF, rank: int, block: int = 8, *, n_iter_max: int = 100,
                   seed: int = 0, progress: bool = False) -> TiledNDF:
    """CP-compressed copy of uncompressed per-tile pyramids (glints paper sec. 4.2 per tile):
    one ``(B, B, n_l^2)`` tensor per (tile, level, angular block), all at ``rank``; ``progress``:
    a progress bar per level on stderr."""
    if not isinstance(wn, TiledNDF) or wn.block:
        raise PrefilterError("wn: expected uncompressed per-tile pyramids (bake_tiles without "
                             "rank)")
    r = as_positive_int(rank, "rank")
    B = as_positive_int(block, "block")
    it = as_positive_int(n_iter_max, "n_iter_max")
    from tqdm import tqdm

    from prefilter.glints.cp import single_threaded_blas

    # small products: a multi-threaded BLAS spent 100x longer waking threads on a busy machine
    with single_threaded_blas():
        levels = tqdm(list(enumerate(wn.images)), desc="CP levels", disable=not progress)
        packed, errs = zip(*(_compress(x, r, B, it, seed + lv) for lv, x in levels))
    return replace(wn, images=tuple(packed), block=B, cp_error=tuple(errs))


def _compress(x, rank, B, n_iter_max, seed):
    """CP triple ``(A, Bf, C)`` (:class:`TiledNDF`) of one level ``x (16, n, n, R, R)`` and its
    relative L2 error."""
    if x.shape[-1] % B:
        raise PrefilterError(f"block: expected a divisor of ndf_res {x.shape[-1]}, got {B}")
    return _compress_tensors(_level_tensors(x, B), x.shape[0], x.shape[1], rank, B, n_iter_max,
                             seed)


def _level_tensors(x, B):
    """The ``(B, B, n^2)`` tensors ``(16 nb^2, B, B, n^2)`` float32 of one level
    ``x (16, n, n, R, R)``, one per (tile, angular block). The fits read them as float64
    (exact), so float64 copies would only double the bake's memory peak."""
    from prefilter.glints import cp as cpmod

    n_t, n, R = x.shape[0], x.shape[1], x.shape[-1]
    nb = R // B
    blocks = cpmod.cut_blocks(x.reshape(n_t, n * n, R, R), B)  # (16, K, nb, nb, B, B)
    tensors = np.ascontiguousarray(blocks.transpose(0, 2, 3, 4, 5, 1), dtype=np.float32)
    return tensors.reshape(n_t * nb * nb, B, B, n * n)


def _sum_squares(x) -> float:
    """``sum(x^2)`` of a float32 array in float64, chunk by chunk (no float64 copy of the whole
    level's tensors: the bake's memory peak)."""
    flat = np.ascontiguousarray(x).reshape(-1)
    step = 1 << 16
    acc = 0.0
    for i in range(0, flat.size, step):
        c = flat[i:i + step].astype(np.float64)
        acc += float(c @ c)
    return acc


def _compress_tensors(tensors, n_t, n, rank, B, n_iter_max, seed):
    """:func:`_compress` of the level's :func:`_level_tensors` (``n_t`` tiles, ``n^2``
    centres)."""
    from prefilter.glints.cp import single_threaded_blas

    # small products: a multi-threaded BLAS spent 100x longer waking threads on a busy machine
    with single_threaded_blas():
        return _fit_level(tensors, n_t, n, rank, B, n_iter_max, seed)


def _fit_level(tensors, n_t, n, rank, B, n_iter_max, seed):
    from prefilter.glints import cp as cpmod

    nb = math.isqrt(tensors.shape[0] // n_t)
    K = n * n
    live = np.flatnonzero(tensors.max(axis=(1, 2, 3)) > 0.0)
    A = np.zeros((n_t * nb * nb, rank, B), np.float32)
    Bf = np.zeros_like(A)
    C = np.zeros((n_t * nb * nb, K, rank), np.float32)
    fits = cpmod.nn_cp_batch([tensors[g] for g in live], rank, n_iter_max=n_iter_max, seed=seed)
    err2 = 0.0
    for g, (a, b, c, _) in zip(live, fits):
        A[g], Bf[g], C[g] = a.T, b.T, c
        d = cpmod.reconstruct(A[g].T.astype(np.float64), Bf[g].T.astype(np.float64),
                              C[g].astype(np.float64)) - tensors[g].astype(np.float64)
        err2 += float(np.einsum("ijk,ijk->", d, d))
    C = C.reshape(n_t, nb * nb, n, n, rank).transpose(0, 2, 3, 1, 4)
    packed = (A.reshape(n_t, nb * nb, rank, B), Bf.reshape(n_t, nb * nb, rank, B),
              np.ascontiguousarray(C))
    return packed, math.sqrt(err2 / max(_sum_squares(tensors), 1e-300))


# ---------------------------------------------------------------------------------------------
# queries


def _lookup(wn: TiledNDF, index, i, j):
    if index is None:
        return tile_index(wn.wang, i, j)
    ny, nx = index.shape
    return index[np.asarray(j) % ny, np.asarray(i) % nx]


def _as_index(index):
    if index is None:
        return None
    a = np.asarray(index)
    if a.ndim != 2 or not np.issubdtype(a.dtype, np.integer) or a.size == 0 \
            or a.min() < 0 or a.max() > 15:
        raise PrefilterError(f"index: expected a 2D integer tile index map in [0, 15], got "
                             f"{a.dtype} {a.shape}")
    return a


#: Resampling taps within this many stds of the resampling kernel (``pyramid.resample_weights``
#: uses 3: cutting it there narrows the footprint by ~1 %, which moves the tile shares of a
#: footprint on a tile corner by ~3e-3).
_TAP_TRUNCATION = 4.0
#: Smallest std of a resampling tap's product Gaussian in strides (``pyramid.RESAMPLE_Q_MIN`` is
#: 0.45): the Riemann sum over centres aliases like ``exp(-2 pi^2 q^2)``, 2 % at 0.45 for the sharp
#: per-tile contributions, 8e-4 at 0.6; below it the direct P-NDF is used.
_Q_MIN = 0.6


def footprint_regime(wn: TiledNDF, sp: float) -> str:
    """Which of the four regimes (module docstring) serves a footprint of std ``sp``:
    ``"direct"``, ``"tiles"``, ``"shares"`` or ``"uniform"``."""
    if sp < wn.min_sigma:
        return "direct"
    if sp >= wn.uniform_sigma:
        return "uniform"
    return "shares" if sp >= wn.wide_sigma else "tiles"


#: The in-tile moments of the tile-type shares regime beyond the shares themselves: degree
#: pairs ``(dy, dx)`` of :func:`moment_basis`'s polynomials in a texel's row and column within
#: its tile (total degree <= 2). Position ``k + 1`` of :func:`type_moments`' columns.
MOMENT_PAIRS = ((0, 1), (1, 0), (0, 2), (1, 1), (2, 0))
_PAIRS = np.array(((0, 0),) + MOMENT_PAIRS, np.int64)


def moment_basis(T: int) -> np.ndarray:
    """``(3, T)`` discrete orthonormal polynomials of degree 0, 1, 2 on a tile's texel centres
    ``x + 0.5``: ``(1 / T) sum_x p_a(x) p_b(x) = delta_ab``, ``p_0 = 1``, ``p_1`` increasing,
    ``p_2`` positive at the edges."""
    x = np.arange(T) + 0.5 - 0.5 * T
    q, _ = np.linalg.qr(np.stack([np.ones(T), x, x * x], axis=1))
    p = q.T * math.sqrt(T)
    return p * np.sign(p[:, -1:])


def _positional_covariance(Jx, Jy, var):
    """``(a, b, d)`` of ``var J J^T`` for texels' slope derivatives ``Jx = ds/dx``, ``Jy =
    ds/dy`` ``(..., 2)``: the positional part of their elements' covariance (NumPy arrays;
    ``pndf.element_covariance`` is the compiled scalar form)."""
    return (var * (Jx[..., 0] ** 2 + Jy[..., 0] ** 2),
            var * (Jx[..., 0] * Jx[..., 1] + Jy[..., 0] * Jy[..., 1]),
            var * (Jx[..., 1] ** 2 + Jy[..., 1] ** 2))


def tile_moment_images(wt: WangTiles, resolution: int, support: float, intrinsic_roughness: float,
                       pairs=MOMENT_PAIRS) -> np.ndarray:
    """``(16, K, R, R)`` float64 in-tile moment images ``E_k = (1 / T^2) sum_i p_dy(y_i)
    p_dx(x_i) N_i`` of each tile's ``sigma_p -> inf`` elements (the texels of
    :func:`tile_elements` as in ``tile_means``; ``pairs[k] = (dy, dx)``, :func:`moment_basis`):
    the projection of the texels' NDFs on polynomials of their position in the tile. The pair
    ``(0, 0)`` is ``tile_means``."""
    T = wt.size
    R = as_positive_int(resolution, "resolution")
    S = as_support(support)
    sr = as_intrinsic_roughness(intrinsic_roughness)
    P = moment_basis(T)
    s_el, J = tile_elements(wt)
    a, b, d = _positional_covariance(J[..., :, 0], J[..., :, 1], SIGMA_H**2)
    K = len(pairs)
    w = np.stack([np.outer(P[dy], P[dx]) / (T * T) for dy, dx in pairs])  # (K, T, T)
    which = (np.arange(16)[:, None, None, None] * K + np.arange(K)[None, :, None, None])
    which = np.broadcast_to(which, (16, K, T, T)).ravel()

    def per_k(v):
        return np.ascontiguousarray(np.broadcast_to(v[:, None], (16, K, T, T)).ravel())

    h = 2.0 * S / R
    imgs = np.zeros((16 * K, R, R))
    _splat_elements(per_k(s_el[..., 0]), per_k(s_el[..., 1]), per_k(a), per_k(b), per_k(d),
                    np.ascontiguousarray(np.broadcast_to(w, (16, K, T, T)).ravel()),
                    np.ascontiguousarray(which), sr, -S, h, TRUNCATION, imgs)
    return imgs.reshape(16, K, R, R) / (h * h)


def moment_tables(images: np.ndarray) -> np.ndarray:
    """Summed-area tables ``(R + 1, R + 1, 16, K)`` float32 of images ``(16, K, R, R)``, pixel
    units, position-major (a lookup reads the 16 K values of one position together); summed
    in float64: the signed moment images' tables lose < 3e-4 of a density to the float32
    rounding at R = 256 (measured)."""
    im = np.asarray(images, np.float64)
    out = np.zeros((im.shape[2] + 1, im.shape[3] + 1) + im.shape[:2], np.float32)
    out[1:, 1:] = im.cumsum(axis=2).cumsum(axis=3).transpose(2, 3, 0, 1)
    return out


def pooled_tables(sat: np.ndarray, pool: int) -> np.ndarray:
    """:func:`moment_tables` of the images averaged over ``pool x pool`` pixels, from the
    tables of the full-resolution ones."""
    return np.ascontiguousarray(sat[::pool, ::pool] / np.float32(pool * pool))


def type_shares(wn: TiledNDF, center, sigma_p, *, index=None) -> np.ndarray:
    """``(16,)`` share of one footprint's weight on each tile type: the direct P-NDF's Gaussian
    weights over its truncation window (separable sums per tile row and column), summed by
    type. Cost: O(tiles under the footprint)."""
    c, sp, index = _prepare(wn, center, sigma_p, index)
    return _type_moments(wn, c, sp, index)[:, 0]


def type_moments(wn: TiledNDF, center, sigma_p, *, index=None) -> np.ndarray:
    """``(16, 6)`` per tile type: the footprint's normalised weights summed over the texels of
    that type's tiles times ``p_dy(y) p_dx(x)`` (:func:`moment_basis`, the texel's place in its
    tile) for ``(dy, dx)`` = ``(0, 0)`` (column 0: :func:`type_shares`) and
    :data:`MOMENT_PAIRS`. The tile-type shares regime's NDF is
    ``sum_t sum_k moments[t, k] E_tk`` (:func:`tile_moment_images`): each texel's NDF
    projected on quadratics of its position in the tile (exact for the shares' part)."""
    c, sp, index = _prepare(wn, center, sigma_p, index)
    return _type_moments(wn, c, sp, index)


def _type_moments(wn, c, sp, index):
    T = wn.wang.size
    P = moment_basis(T)
    tot2 = sp * sp + SIGMA_H**2
    rad = TRUNCATION * math.sqrt(tot2)
    per_axis = []
    for a in (0, 1):
        x = np.arange(math.ceil(c[a] - rad - 0.5), math.floor(c[a] + rad - 0.5) + 1)
        w = np.exp(-(c[a] - x - 0.5) ** 2 / (2.0 * tot2))
        tiles, inv = np.unique(x // T, return_inverse=True)
        m = np.stack([np.bincount(inv, weights=w * P[d, x % T]) for d in range(3)], axis=-1)
        per_axis.append((tiles, m / w.sum()))
    (ti, mi), (tj, mj) = per_axis
    t = _lookup(wn, index, ti[None, :], tj[:, None]).ravel()
    return np.stack([np.bincount(t, weights=np.outer(mj[:, dy], mi[:, dx]).ravel(),
                                 minlength=16) for dy, dx in _PAIRS], axis=-1)


def _moment_pixels(wn: TiledNDF, iy, ix) -> np.ndarray:
    """``(16, 5, ...)`` values of the moment images at pixels ``(iy, ix)`` from their tables."""
    S = wn.moment_sat.astype(np.float64)
    v = S[iy + 1, ix + 1] - S[iy, ix + 1] - S[iy + 1, ix] + S[iy, ix]  # (..., 16, 5)
    return np.moveaxis(v, (-2, -1), (0, 1))


def _shares_values(wn: TiledNDF, c, sp, index, iy, ix) -> np.ndarray:
    """The tile-type shares regime's NDF at pixels ``(iy, ix)``: ``sum_t sum_k moments[t, k]
    E_tk``, clamped at 0 (the quadratic projection can dip below)."""
    mom = _type_moments(wn, c, sp, index)
    v = np.einsum("t,t...->...", mom[:, 0], wn.tile_means[:, iy, ix])
    if wn.moment_sat is not None:
        v = v + np.einsum("tk,tk...->...", mom[:, 1:], _moment_pixels(wn, iy, ix))
    return np.maximum(v, 0.0)


def _level(wn: TiledNDF, sp: float) -> int:
    """Coarsest level whose footprints resample ``sp`` (``pyramid.resample_weights``' rule)."""
    m = 0
    for lv in range(wn.n_levels):
        sg = wn.sigma(lv)
        if sg < sp and math.sqrt(1.0 - (sg / sp) ** 2) * sg / wn.stride(lv) >= _Q_MIN:
            m = lv
    return m


def _axis_taps(wn: TiledNDF, m: int, c: float, r: float, n_tiles_lo: int, n_tiles_hi: int):
    """Per tile column ``i`` in ``[n_tiles_lo, n_tiles_hi]``: crop indices and weights of the
    Gaussian resampling taps along one axis on that tile's centre grid (tile-relative; the grids
    of neighbouring tiles differ when the stride does not divide the tile), the weights
    normalised over all of the tile's taps."""
    st = wn.stride(m)
    T = wn.wang.size
    half = _TAP_TRUNCATION * r / st
    n = wn.crop(m)
    out = []
    for i in range(n_tiles_lo, n_tiles_hi + 1):
        cr = c - i * T
        g = (cr - 0.5) / st
        k = np.arange(math.ceil(g - half), math.floor(g + half) + 1)
        w = np.exp(-0.5 * ((k * st + 0.5 - cr) / r) ** 2)
        w /= w.sum()
        a = k - wn.k0[m]  # crop index
        keep = (a >= 0) & (a < n)
        out.append((i, a[keep], w[keep]))
    return out


def _tiles_window(wn: TiledNDF, c, sp):
    T = wn.wang.size
    rad = _margin(sp)
    return (math.floor((c[0] - rad) / T), math.floor((c[0] + rad) / T),
            math.floor((c[1] - rad) / T), math.floor((c[1] + rad) / T))


def _tile_terms(wn: TiledNDF, c, sp, index):
    """Level and ``(i, j, t, ay, wy, ax, wx)`` per tile under the footprint's window (taps in
    the tile's crop, possibly none)."""
    m = _level(wn, sp)
    r = math.sqrt(sp * sp - wn.sigma(m) ** 2)
    # the tiles with texels in the direct P-NDF's truncation window (the taps' footprints reach
    # further, but what they add there is the Gaussian's tail beyond TRUNCATION stds)
    i0, i1, j0, j1 = _tiles_window(wn, c, sp)
    xs = _axis_taps(wn, m, float(c[0]), r, i0, i1)
    ys = _axis_taps(wn, m, float(c[1]), r, j0, j1)
    terms = [(i, j, ay, wy, ax, wx) for j, ay, wy in ys for i, ax, wx in xs]
    t = _lookup(wn, index, np.array([x[0] for x in terms]), np.array([x[1] for x in terms]))
    return m, [(i, j, int(tt), ay, wy, ax, wx) for (i, j, ay, wy, ax, wx), tt in zip(terms, t)]


@njit_serial
def _splat_elements(mx, my, a, b, d, w, which, sr, lo, h, trunc, imgs):
    """Add ``w_k`` times element ``k``'s pixel masses to ``imgs[which_k]``
    (:func:`prefilter.glints.pndf.splat_element`, the splatting of the direct P-NDF's images)."""
    px = np.zeros_like(imgs[0, 0])
    py = np.zeros_like(imgs[0, 0])
    for k in range(mx.shape[0]):
        splat_element(imgs[which[k]], px, py, mx[k], my[k], a[k], b[k], d[k], sr, w[k], lo, h,
                      trunc)


def _texel_s(wn: TiledNDF, index, gx, gy):
    """Projected normals ``(..., 2)`` of global texels ``(gx, gy)`` of the tiled plane."""
    T = wn.wang.size
    t = _lookup(wn, index, gx // T, gy // T)
    return wn.wang.tiles[t, gy % T, gx % T, :2]


def _dependent_images(wn: TiledNDF, c, sp, index, ij):
    """Contributions ``(k, R, R)`` of the dependent texels (:func:`dependent_texels`) of the
    tiles ``ij (k, 2)``, with their exact Jacobians (the actual neighbours, looked up) and the
    direct P-NDF's weights and normalisation (Yan et al. 2016 closed-form elements)."""
    T, R = wn.wang.size, wn.resolution
    imgs = np.zeros((len(ij), R, R))
    if not len(ij) or not len(wn.dependent):
        return imgs
    sh2 = SIGMA_H**2
    tot2 = sp * sp + sh2
    rad = TRUNCATION * math.sqrt(tot2)
    lo_x, hi_x = math.ceil(c[0] - rad - 0.5), math.floor(c[0] + rad - 0.5)
    lo_y, hi_y = math.ceil(c[1] - rad - 0.5), math.floor(c[1] + rad - 0.5)
    # the direct P-NDF's normaliser: all texels of the window, a separable sum
    wsum = (np.exp(-(c[0] - np.arange(lo_x, hi_x + 1) - 0.5) ** 2 / (2 * tot2)).sum()
            * np.exp(-(c[1] - np.arange(lo_y, hi_y + 1) - 0.5) ** 2 / (2 * tot2)).sum())
    gx = (ij[:, :1] * T + wn.dependent[None, :, 1]).ravel()
    gy = (ij[:, 1:] * T + wn.dependent[None, :, 0]).ravel()
    which = np.repeat(np.arange(len(ij)), len(wn.dependent))
    keep = (gx >= lo_x) & (gx <= hi_x) & (gy >= lo_y) & (gy <= hi_y)
    gx, gy, which = gx[keep], gy[keep], which[keep]
    s0 = _texel_s(wn, index, gx, gy)
    Jx = 0.5 * (_texel_s(wn, index, gx + 1, gy) - _texel_s(wn, index, gx - 1, gy))
    Jy = 0.5 * (_texel_s(wn, index, gx, gy + 1) - _texel_s(wn, index, gx, gy - 1))
    dx = c[0] - (gx + 0.5)
    dy = c[1] - (gy + 0.5)
    f, var = sh2 / tot2, sp * sp * sh2 / tot2
    mean = s0 + f * (Jx * dx[:, None] + Jy * dy[:, None])
    a, b, d = _positional_covariance(Jx, Jy, var)
    w = np.exp(-(dx * dx + dy * dy) / (2 * tot2))
    cc = np.ascontiguousarray
    h = 2.0 * wn.support / R
    _splat_elements(cc(mean[:, 0]), cc(mean[:, 1]), a, b, d, w, which.astype(np.int64),
                    wn.intrinsic_roughness, -wn.support, h, TRUNCATION, imgs)
    return imgs / (wsum * h * h)


def _prepare(wn, center, sigma_p, index):
    if not isinstance(wn, TiledNDF):
        raise PrefilterError(f"wn: expected a TiledNDF (bake_tiles), got {type(wn).__name__}")
    return as_center(center), as_one_sigma_p(sigma_p), _as_index(index)


def _direct_image(wn: TiledNDF, c, sp, index):
    if index is None:
        return pndf_image_implicit(wn.wang, c, sp, wn.resolution, wn.support,
                                   wn.intrinsic_roughness)
    T = wn.wang.size
    i0, j0, nx, ny = tile_window(wn.wang, c, sp)
    J, I = np.meshgrid(np.arange(ny) + j0, np.arange(nx) + i0, indexing="ij")
    local = assemble(wn.wang, _lookup(wn, index, I, J))
    return pndf_image(local, c - np.array([i0 * T, j0 * T]), sp, wn.resolution, wn.support,
                      wn.intrinsic_roughness)


def contributions(wn: TiledNDF, center, sigma_p, *, index=None):
    """Per-tile contributions to one footprint's NDF image (paper sec. 5.5, Fig. 12).

    Parameters
    ----------
    wn : TiledNDF; center : (2,) texels, any position; sigma_p : footprint std in texels.
    index : optional explicit ``(ny, nx)`` tile index map (periodic, tile ``(0, 0)`` at the
        origin) instead of the implicit hashing.

    Returns
    -------
    ij : (k, 2) tile coordinates ``(i, j)``; images : (k, R, R) their contributions, each
    carrying its share of the footprint mass; their sum is the footprint's NDF image. For
    footprints below ``wn.min_sigma`` (direct P-NDF) or at/above ``wn.uniform_sigma``
    (tile-independent NDF) ``ij`` is empty and ``images`` holds the one image; between
    ``wn.wide_sigma`` and ``wn.uniform_sigma`` ``ij`` is empty and ``images (1, R, R)`` is the
    tile-type shares regime's image (:func:`type_moments`).
    """
    c, sp, index = _prepare(wn, center, sigma_p, index)
    regime = footprint_regime(wn, sp)
    none = np.zeros((0, 2), np.int64)
    if regime == "direct":
        return none, _direct_image(wn, c, sp, index)[None]
    if regime == "uniform":
        return none, wn.mean[None].copy()
    if regime == "shares":
        R = wn.resolution
        iy, ix = np.divmod(np.arange(R * R), R)
        return none, _shares_values(wn, c, sp, index, iy, ix).reshape(1, R, R)
    m, terms = _tile_terms(wn, c, sp, index)
    ij = np.array([(x[0], x[1]) for x in terms], np.int64).reshape(-1, 2)
    imgs = _dependent_images(wn, c, sp, index, ij)
    for n, (_, _, t, ay, wy, ax, wx) in enumerate(terms):
        if ay.size and ax.size:
            imgs[n] += _tap_image(wn, m, t, ay, wy, ax, wx)
    return ij, imgs


def _tap_image(wn: TiledNDF, m, t, ay, wy, ax, wx) -> np.ndarray:
    """``sum_taps w image`` ``(R, R)`` of tile type ``t`` at level ``m``; compressed: the taps
    blend the ``C`` rows first (``rank`` numbers per block instead of ``B^2``). ``einsum``
    without BLAS: small products, and BLAS threads cost more than they save here."""
    lv = wn.images[m]
    W = np.outer(wy, wx)
    if isinstance(lv, np.ndarray):
        return np.einsum("ab,abij->ij", W, lv[t][ay[:, None], ax[None, :]])
    A, Bf, C = lv
    coef = np.einsum("ab,abgr->gr", W, C[t][ay[:, None], ax[None, :]])
    B, R = wn.block, wn.resolution
    nb = R // B
    blocks = np.einsum("gr,gri,grj->gij", coef, A[t], Bf[t])
    return blocks.reshape(nb, nb, B, B).swapaxes(1, 2).reshape(R, R)


def _tap_points(wn: TiledNDF, m, t, ay, wy, ax, wx, py, px) -> np.ndarray:
    """Pixels ``(py, px)`` ``(N,)`` of :func:`_tap_image` without forming the image."""
    lv = wn.images[m]
    W = np.outer(wy, wx)
    if isinstance(lv, np.ndarray):
        return np.einsum("ab,abn->n", W, lv[t][ay[:, None, None], ax[None, :, None], py, px])
    A, Bf, C = lv
    coef = np.einsum("ab,abgr->gr", W, C[t][ay[:, None], ax[None, :]])
    B = wn.block
    g = (py // B) * (wn.resolution // B) + px // B
    return np.einsum("nr,nr,nr->n", coef[g], A[t][g, :, py % B], Bf[t][g, :, px % B])


def ndf_image(wn: TiledNDF, center, sigma_p, *, index=None) -> np.ndarray:
    """NDF image ``(R, R)`` of one footprint over the tiled plane: sum of the tile contributions
    (direct P-NDF below ``wn.min_sigma``, tile-type shares from ``wn.wide_sigma``, the
    tile-independent NDF from ``wn.uniform_sigma``)."""
    return contributions(wn, center, sigma_p, index=index)[1].sum(axis=0)


def _pixels(wn: TiledNDF, s):
    q = as_float_array(s, "s", ndim_min=1, last_dim=2)
    R, S = wn.resolution, wn.support
    h = 2.0 * S / R
    ix = np.floor((q[..., 0] + S) / h).astype(np.int64)
    iy = np.floor((q[..., 1] + S) / h).astype(np.int64)
    inside = (ix >= 0) & (ix < R) & (iy >= 0) & (iy < R)
    return np.clip(iy, 0, R - 1), np.clip(ix, 0, R - 1), inside


def ndf(wn: TiledNDF, center, sigma_p, s, *, index=None) -> np.ndarray:
    """NDF values ``(...)`` of one footprint at ``s (..., 2)``: the value of the image pixel
    holding ``s`` (0 outside the support), summed over the tiles under the footprint.

    Cost per ``s``: taps x tiles under the footprint below ``wn.wide_sigma``, 6 values per tile
    type above (plus O(tiles) for the shares below ``wn.uniform_sigma``): bounded."""
    c, sp, index = _prepare(wn, center, sigma_p, index)
    iy, ix, inside = _pixels(wn, s)
    regime = footprint_regime(wn, sp)
    if regime == "direct":
        v = _direct_image(wn, c, sp, index)[iy, ix]
    elif regime == "uniform":
        v = wn.mean[iy, ix]
    elif regime == "shares":
        v = _shares_values(wn, c, sp, index, iy, ix)
    else:
        m, terms = _tile_terms(wn, c, sp, index)
        ij = np.array([(x[0], x[1]) for x in terms], np.int64).reshape(-1, 2)
        v = _dependent_images(wn, c, sp, index, ij).sum(axis=0)[iy, ix]
        py, px = iy.reshape(-1), ix.reshape(-1)
        for _, _, t, ay, wy, ax, wx in terms:
            if ay.size and ax.size:
                v += _tap_points(wn, m, t, ay, wy, ax, wx, py, px).reshape(iy.shape)
    return np.where(inside, v, 0.0)


def ndf_pdf(wn: TiledNDF, center, sigma_p, s, *, index=None) -> np.ndarray:
    """Density w.r.t. ``s`` that :func:`sample` draws: :func:`ndf` over the image's mass."""
    img = ndf_image(wn, center, sigma_p, index=index)
    M = img.sum() * (2.0 * wn.support / wn.resolution) ** 2
    iy, ix, inside = _pixels(wn, s)
    return np.where(inside & (M > 0), img[iy, ix] / max(M, 1e-300), 0.0)


def sample(wn: TiledNDF, center, sigma_p, n: int, rng=0, *, index=None):
    """``n`` projected half vectors distributed as one footprint's NDF image (sec. 5.5).

    A tile contribution is chosen with probability proportional to its mass (the paper picks
    tiles uniformly; by mass the samples follow the sum exactly), then a pixel of it by its
    inverse CDF, then a uniform point in the pixel.

    Returns
    -------
    s : (n, 2); pdf : (n,) the density of ``s``: ``image(pixel) / mass`` (the mixture over the
    contributions, equal to :func:`ndf_pdf`); 0 for an empty image.
    """
    n = as_positive_int(n, "n")
    gen = as_rng(rng)
    _, imgs = contributions(wn, center, sigma_p, index=index)
    R, S = wn.resolution, wn.support
    h = 2.0 * S / R
    flat = imgs.reshape(len(imgs), -1)
    masses = flat.sum(axis=1)
    total = masses.sum()
    if total <= 0:
        return np.zeros((n, 2)), np.zeros(n)
    part = np.minimum(np.searchsorted(np.cumsum(masses) / total, gen.random(n), side="right"),
                      len(masses) - 1)
    pix = np.empty(n, np.int64)
    u = gen.random(n)
    for k in np.unique(part):
        sel = part == k
        cdf = np.cumsum(flat[k])
        cdf /= cdf[-1]
        pix[sel] = np.minimum(np.searchsorted(cdf, u[sel], side="right"), R * R - 1)
    iy, ix = np.divmod(pix, R)
    edges = pixel_edges(R, S)
    jit = gen.random((n, 2))
    s = np.stack([edges[ix] + h * jit[:, 0], edges[iy] + h * jit[:, 1]], axis=-1)
    img = flat.sum(axis=0)
    return s, img[pix] / (total * h * h)


# ---------------------------------------------------------------------------------------------
# batched point queries (Numba): the same arithmetic as ndf(), one kernel for many footprints

@njit_serial
def _nb_type(i, j, seed, index):  # pragma: no cover - compiled; _lookup
    if index.shape[0] > 0:
        return index[j % index.shape[0], i % index.shape[1]]
    return implicit_type(i, j, seed)


@njit_serial
def _nb_types(i0, i1, j0, j1, seed, index):  # pragma: no cover - compiled
    """Tile types ``(j1 - j0 + 1, i1 - i0 + 1)`` of a block of tiles (:func:`_nb_type`); on
    the implicit tiling each grid vertex hashed once (``implicit_type`` hashes three per
    tile)."""
    ny, nx = j1 - j0 + 1, i1 - i0 + 1
    out = np.empty((ny, nx), np.int64)
    if index.shape[0] > 0:
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                out[j - j0, i - i0] = index[j % index.shape[0], i % index.shape[1]]
        return out
    right = np.empty((ny + 1, nx + 1), np.int64)  # colour of each vertex's right edge
    below = np.empty((ny + 1, nx + 1), np.int64)  # and of its lower edge
    for j in range(ny + 1):
        for i in range(nx + 1):
            right[j, i], below[j, i] = hash_bits(i0 + i, j0 + j, seed)
    for j in range(ny):
        for i in range(nx):
            out[j, i] = edge_type(right[j, i], right[j + 1, i], below[j, i], below[j, i + 1])
    return out


@njit_serial
def level_window(s, c0, c1, sigma0, st0, L, q_min, tap_trunc, crops, k0, rad, T, seed,
                 index):  # pragma: no cover - compiled
    """The pyramid level and tile window of a footprint of std ``s`` centred at ``(c0, c1)``
    (texels) that the tiled point and range queries read: the coarsest level ``m`` whose
    resampling kernel (std ``sqrt(s^2 - sigma_m^2)``) still spans ``q_min`` strides, its crop
    size ``n``, the first tile ``(ti0, tj0)`` and tile types of the window ``rad + 1`` texels
    around the centre, the tile rows ``jlo..jhi`` and columns ``ilo..ihi`` it reads, and
    :func:`prefilter.glints.wang_query.tile_taps`' taps ``wyt, wxt, kyl, kyh, kxl, kxh``."""
    m = 0
    for lv in range(L):
        sg = sigma0 * 2.0**lv
        st = st0 * 2.0**lv
        if sg < s and math.sqrt(1.0 - (sg / s) ** 2) * sg / st >= q_min:
            m = lv
    n = crops[m]
    marg = rad + 1.0
    ti0 = int(math.floor((c0 - marg) / T)) - 1
    tj0 = int(math.floor((c1 - marg) / T)) - 1
    types = _nb_types(ti0, int(math.floor((c0 + marg) / T)) + 1, tj0,
                      int(math.floor((c1 + marg) / T)) + 1, seed, index)
    (jlo, jhi, ilo, ihi, wyt, wxt, kyl, kyh, kxl,
     kxh) = window_taps(s, c0, c1, m, n, sigma0, st0, tap_trunc, k0[m], rad, T, 0.0)
    return m, n, ti0, tj0, types, jlo, jhi, ilo, ihi, wyt, wxt, kyl, kyh, kxl, kxh


@njit_serial
def window_taps(s, c0, c1, m, n, sigma0, st0, tap_trunc, km, rad, T,
                shift):  # pragma: no cover - compiled
    """The ``T x T`` tiles of a grid shifted by ``-shift`` texels per axis (tile ``i`` covers
    ``iT - shift .. iT - shift + T``) within ``rad + 1`` texels of a footprint of std ``s``
    centred at ``(c0, c1)``: rows ``jlo..jhi``, columns ``ilo..ihi``, and their resampling taps
    at level ``m`` (std ``sqrt(s^2 - sigma_m^2)``, crop of ``n`` centres from ``km``;
    :func:`prefilter.glints.wang_query.tile_taps`)."""
    sg = sigma0 * 2.0**m
    st = st0 * 2.0**m
    r = math.sqrt(s * s - sg * sg)
    marg = rad + 1.0
    jlo = int(math.floor((c1 - marg + shift) / T))
    jhi = int(math.floor((c1 + marg + shift) / T))
    ilo = int(math.floor((c0 - marg + shift) / T))
    ihi = int(math.floor((c0 + marg + shift) / T))
    wyt, wxt, kyl, kyh, kxl, kxh = tile_taps(c1 + shift, c0 + shift, T, st, r,
                                              tap_trunc * r / st, km, n, jlo, jhi, ilo, ihi)
    return jlo, jhi, ilo, ihi, wyt, wxt, kyl, kyh, kxl, kxh


@njit_serial
def vertex_window(s, c0, c1, m, n, sigma0, st0, tap_trunc, km, rad, T, types, ti0,
                  tj0):  # pragma: no cover - compiled
    """The vertex tiles (:func:`vertex_tiles`) a footprint of std ``s`` centred at ``(c0, c1)``
    reads at level ``m`` (crop of ``n`` centres from ``km``), as :func:`level_window` the tiles:
    their configurations ``(rows, cols)`` (from the tile types ``types`` of first tile ``(ti0,
    tj0)``, a valid tiling) and :func:`prefilter.glints.wang_query.tile_taps`' taps on the
    vertex tiles' grids (:func:`window_taps`, the tiles' grids shifted by ``T/2``)."""
    (jlo, jhi, ilo, ihi, wyt, wxt, kyl, kyh, kxl,
     kxh) = window_taps(s, c0, c1, m, n, sigma0, st0, tap_trunc, km, rad, T, 0.5 * T)
    vt = np.empty((jhi - jlo + 1, ihi - ilo + 1), np.int64)
    for j in range(jlo, jhi + 1):
        for i in range(ilo, ihi + 1):
            vt[j - jlo, i - ilo] = vertex_config(types[j - 1 - tj0, i - 1 - ti0],
                                                 types[j - tj0, i - ti0])
    return vt, wyt, wxt, kyl, kyh, kxl, kxh


@njit_serial
def _nb_s(tiles, types, i0, j0, gx, gy, comp):  # pragma: no cover - compiled; _texel_s
    T = tiles.shape[1]
    return tiles[types[gy // T - j0, gx // T - i0], gy % T, gx % T, comp]


@njit_serial
def _nb_axis(lo, h, R, m, rad, iz):  # pragma: no cover - compiled
    # pixel iz's mass along one axis of N(m, .) as pndf.splat gives it (0 outside its pixel range)
    z0 = max(0, int(math.floor((m - rad - lo) / h)))
    z1 = min(R - 1, int(math.floor((m + rad - lo) / h)))
    return z0 <= iz <= z1


@njit_serial
def _nb_pixel(mx, my, siso, w, lo, h, R, trunc, iy, ix):  # pragma: no cover - compiled
    """``w`` times pixel ``(iy, ix)``'s mass of ``N((mx, my), siso^2 I)`` (``pndf.splat``)."""
    rad = trunc * siso
    if not (_nb_axis(lo, h, R, mx, rad, ix) and _nb_axis(lo, h, R, my, rad, iy)):
        return 0.0
    inv = 1.0 / siso
    px = normal_cdf((lo + (ix + 1) * h - mx) * inv) - normal_cdf((lo + ix * h - mx) * inv)
    py = normal_cdf((lo + (iy + 1) * h - my) * inv) - normal_cdf((lo + iy * h - my) * inv)
    return w * py * px


@njit_serial
def _nb_element(mx, my, a, b, d, w, sr, lo, h, R, trunc, iy, ix):  # pragma: no cover
    """Pixel ``(iy, ix)`` of :func:`_splat_elements` for one element."""
    hi = lo + R * h
    nu1, siso, kappa = element_split(a, b, d, sr)
    reach = trunc * math.sqrt(nu1 + sr * sr)
    if mx + reach < lo or mx - reach > hi or my + reach < lo or my - reach > hi:
        return 0.0
    # every node splat lies within trunc (kappa + siso) of the mean: most pixels are beyond
    ext = trunc * (kappa + siso) + h
    if abs(lo + (ix + 0.5) * h - mx) > ext or abs(lo + (iy + 0.5) * h - my) > ext:
        return 0.0
    n, norm = element_nodes(kappa, siso, trunc)
    vx, vy = principal_axis(a, b, d, nu1) if n > 1 else (0.0, 0.0)
    acc = 0.0
    for q in range(n):
        t, num, den, cut = element_node(kappa, trunc, n, norm, q)
        acc += _nb_pixel(mx + t * vx, my + t * vy, siso, w * num / den, lo, h, R, cut, iy, ix)
    return acc


@njit_serial
def _nb_gaussian(tiles, types, i0, j0, gx, gy, cx, cy, f, var, tot2):  # pragma: no cover
    """Footprint weight and element Gaussian (mean ``(mx, my)``, positional covariance
    ``(a, b, d)``, :func:`prefilter.glints.pndf.element_moments`) of texel ``(gx, gy)`` of the
    tiled plane, its slope Jacobian by central differences over the exact neighbours
    (``types`` covers its tile and the neighbouring ones, from tile ``(i0, j0)``)."""
    ty = types
    jx0 = 0.5 * (_nb_s(tiles, ty, i0, j0, gx + 1, gy, 0) - _nb_s(tiles, ty, i0, j0, gx - 1, gy, 0))
    jx1 = 0.5 * (_nb_s(tiles, ty, i0, j0, gx + 1, gy, 1) - _nb_s(tiles, ty, i0, j0, gx - 1, gy, 1))
    jy0 = 0.5 * (_nb_s(tiles, ty, i0, j0, gx, gy + 1, 0) - _nb_s(tiles, ty, i0, j0, gx, gy - 1, 0))
    jy1 = 0.5 * (_nb_s(tiles, ty, i0, j0, gx, gy + 1, 1) - _nb_s(tiles, ty, i0, j0, gx, gy - 1, 1))
    dx = cx - (gx + 0.5)
    dy = cy - (gy + 0.5)
    mx = _nb_s(tiles, ty, i0, j0, gx, gy, 0) + f * (jx0 * dx + jy0 * dy)
    my = _nb_s(tiles, ty, i0, j0, gx, gy, 1) + f * (jx1 * dx + jy1 * dy)
    a, b, d = element_covariance(jx0, jy0, jx1, jy1, var, 0.0)
    return math.exp(-(dx * dx + dy * dy) / (2.0 * tot2)), mx, my, a, b, d


def dependent_neighbours(wn: TiledNDF) -> np.ndarray:
    """``(n_dep, 5, 4)`` int64: for each dependent texel (``wn.dependent``) the tile offset
    ``(dj, di)`` (-1, 0, 1) and tile-relative ``(row, col)`` of itself and of its neighbours
    ``x + 1``, ``x - 1``, ``y + 1``, ``y - 1`` (:func:`dep_gaussian`'s central differences
    without integer divisions)."""
    T = wn.wang.size
    d = np.asarray(wn.dependent, np.int64).reshape(-1, 2)
    off = np.array([[0, 0], [0, 1], [0, -1], [1, 0], [-1, 0]])
    rc = d[:, None, :] + off[None]  # (n, 5, (row, col))
    return np.ascontiguousarray(np.concatenate([rc // T, rc % T], axis=-1), dtype=np.int64)


@njit_serial
def vertex_config(tl, br):  # pragma: no cover - compiled
    """Configuration ``0..15`` of a grid vertex of a valid tiling from the types of the tiles
    above-left ``tl`` and below-right ``br`` of it (ints): the colours of its four edges (right
    ``n(br)``, below ``w(br)``, left ``s(tl)``, above ``e(tl)``; :func:`~prefilter.glints.wang.
    edge_colours`' bits), which fix the corner squares of the four tiles meeting there (``wang``
    module docstring: near a corner the seams cross-fade the two triangles of its edges only)."""
    return (br & 1) + 2 * ((br >> 2) & 1) + 4 * ((tl >> 1) & 1) + 8 * ((tl >> 3) & 1)


def _config_block(wt: WangTiles, k: int) -> np.ndarray:
    """``(2T, 2T, 2)`` slopes of a valid 2 x 2 block of tiles around a vertex of configuration
    ``k`` (:func:`vertex_config`; the colours of the block's outer edges are 0)."""
    n, w, s, e = k & 1, (k >> 1) & 1, (k >> 2) & 1, (k >> 3) & 1
    tl = 2 * s + 8 * e  # n + 2 s + 4 w + 8 e
    tr = 2 * n + 4 * e
    bl = s + 8 * w
    br = n + 4 * w
    S = wt.tiles[..., :2]
    return np.concatenate([np.concatenate([S[tl], S[tr]], axis=1),
                           np.concatenate([S[bl], S[br]], axis=1)], axis=0)


def vertex_elements(wn: TiledNDF) -> np.ndarray:
    """``(16, n_dep, 8)`` float64: per vertex configuration (:func:`vertex_config`) the elements
    of the dependent texels of the four tiles' corners at the vertex: offset ``(ox, oy)`` of the
    texel from the vertex (texel ``(iT + ox, jT + oy)`` of vertex ``(i, j)``), slope ``(s_x,
    s_y)`` and Jacobian ``(j00, j01, j10, j11)`` (``element_covariance``'s order) by central
    differences. A static table: the queries read a dependent texel's element from it instead
    of looking up its neighbour tiles (exact on a valid tiling; tested against the assembled
    neighbours)."""
    return _vertex_rows(wn.wang, np.asarray(wn.dependent, np.int64).reshape(-1, 2))


def _vertex_rows(wt: WangTiles, dep: np.ndarray) -> np.ndarray:
    """:func:`vertex_elements` of tiles ``wt`` and dependent texels ``dep (n_dep, 2)``."""
    T = wt.size
    out = np.empty((16, len(dep), 8))
    # the corner of its tile each dependent texel is at, as the tile's offset from the vertex
    qy = np.where(dep[:, 0] < T // 2, 0, -1)
    qx = np.where(dep[:, 1] < T // 2, 0, -1)
    gy = T + qy * T + dep[:, 0]  # row in the block, the vertex at (T, T)
    gx = T + qx * T + dep[:, 1]
    for k in range(16):
        S = _config_block(wt, k)
        out[k, :, 0] = gx - T
        out[k, :, 1] = gy - T
        out[k, :, 2:4] = S[gy, gx]
        jx = 0.5 * (S[gy, gx + 1] - S[gy, gx - 1])
        jy = 0.5 * (S[gy + 1, gx] - S[gy - 1, gx])
        out[k, :, 4], out[k, :, 5] = jx[:, 0], jy[:, 0]
        out[k, :, 6], out[k, :, 7] = jx[:, 1], jy[:, 1]
    return out


def vertex_tiles(wt: WangTiles, dep: np.ndarray):
    """The dependent texels of each vertex configuration as the elements of a ``T x T``
    *vertex tile* centred on the vertex (vertex ``(i, j)``'s tile covers texels ``iT - T/2 ..
    iT + T/2 - 1`` per axis, so texel ``(iT + ox, jT + oy)`` is its texel ``(T/2 + oy, T/2 +
    ox)``): slopes ``(16, T, T, 2)``, Jacobians ``(16, T, T, 2, 2)`` and the mask ``(16, T,
    T)`` of the texels that are dependent (:func:`dependent_texels` ``dep (T, T)``). The
    vertex tiles of a valid tiling partition its dependent texels as the tiles partition the
    others, so their pyramids (:func:`bake_tiles`) complete the per-tile ones."""
    T = wt.size
    vel = _vertex_rows(wt, np.argwhere(dep))
    s = np.zeros((16, T, T, 2))
    J = np.zeros((16, T, T, 2, 2))
    keep = np.zeros((16, T, T), bool)
    ly = T // 2 + vel[0, :, 1].astype(np.int64)
    lx = T // 2 + vel[0, :, 0].astype(np.int64)
    s[:, ly, lx] = vel[..., 2:4]
    J[:, ly, lx] = vel[..., 4:8].reshape(16, -1, 2, 2)
    keep[:, ly, lx] = True
    return s, J, keep


@njit_serial
def footprint_rows(c0, c1, s, sh, trunc):  # pragma: no cover - compiled
    """The truncation window of footprint ``(c0, c1)``, std ``s`` (texels; element std ``sh``,
    ``trunc`` stds): ``tot2 = s^2 + sh^2``, its radius and the texel columns ``wx0..wx1`` and
    rows ``wy0..wy1`` whose centres it holds (the direct P-NDF's window)."""
    tot2 = s * s + sh * sh
    rad = trunc * math.sqrt(tot2)
    return (tot2, rad, int(math.ceil(c0 - rad - 0.5)), int(math.floor(c0 + rad - 0.5)),
            int(math.ceil(c1 - rad - 0.5)), int(math.floor(c1 + rad - 0.5)))


@njit_serial
def direct_gaussians(planes, vplanes, vofs, T, types, ti0, tj0, wx0, wx1, wy0, wy1, gxw, gyw, c0,
                     c1, f, var, sr2):  # pragma: no cover - compiled
    """The elements of the texels ``[wx0, wx1] x [wy0, wy1]`` of the implicit tiling as the
    Gaussians ``G (6, n)`` of ``brdf._row_gaussians`` (footprint weights ``gxw``, ``gyw``;
    ``types`` from tile ``(ti0, tj0)``), formed once per footprint for all its points
    (:func:`gaussians_density`): from :func:`tile_planes` ``planes (6, 16, T, T)`` by row
    segments (``glints-direct``'s vectorised form), the dependent texels' from the vertex table
    (:func:`vertex_planes` ``vplanes (6, 16, 1, n_dep)`` at offsets ``vofs (n_dep, 2)`` from
    their vertex), written over the tiles' expected-neighbour values."""
    nx = wx1 - wx0 + 1
    G = np.empty((6, nx * (wy1 - wy0 + 1)))
    fdx = np.empty(nx)
    for x in range(nx):
        fdx[x] = f * (c0 - (wx0 + x + 0.5))
    SX, SY, J00, J01, J10, J11 = planes[0], planes[1], planes[2], planes[3], planes[4], planes[5]
    for y in range(wy0, wy1 + 1):
        ty = y // T
        ry = y - ty * T
        fdy = f * (c1 - (y + 0.5))
        o = (y - wy0) * nx
        for i in range(wx0 // T, wx1 // T + 1):
            tt = types[ty - tj0, i - ti0]
            xa = max(wx0, i * T)
            xb = min(wx1, i * T + T - 1)
            _row_gaussians(J00[tt], J01[tt], J10[tt], J11[tt], SX[tt], SY[tt], ry, xa - i * T,
                           xb - xa + 1, fdx[xa - wx0:], fdy, var, sr2, gxw[xa - wx0:],
                           gyw[y - wy0], G, o + xa - wx0)
    VX, VY, V00, V01, V10, V11 = (vplanes[0], vplanes[1], vplanes[2], vplanes[3], vplanes[4],
                                  vplanes[5])
    for j in range(wy0 // T, wy1 // T + 2):
        for i in range(wx0 // T, wx1 // T + 2):
            k = vertex_config(types[j - 1 - tj0, i - 1 - ti0], types[j - tj0, i - ti0])
            for e in range(VX.shape[2]):
                x = i * T + vofs[e, 0]
                y = j * T + vofs[e, 1]
                if not (wx0 <= x <= wx1 and wy0 <= y <= wy1):
                    continue
                _row_gaussians(V00[k], V01[k], V10[k], V11[k], VX[k], VY[k], 0, e, 1,
                               fdx[x - wx0:], f * (c1 - (y + 0.5)), var, sr2, gxw[x - wx0:],
                               gyw[y - wy0], G, (y - wy0) * nx + x - wx0)
    return G


@njit_serial
def gaussians_density(G, n, qx, qy, t):  # pragma: no cover - compiled
    """``sum_i G[5, i] exp(G's exponent at (qx, qy)) / (2 pi)`` over the first ``n`` Gaussians
    of ``G`` (``brdf._row_gaussians``' layout), each cut at 6 stds (``brdf._ANGULAR_CUT``, as
    ``glints-direct``); ``t (>= n,)`` scratch."""
    _exponents(qx, qy, G, n, t)
    acc = 0.0
    for m in range(n):
        if t[m] > _ANGULAR_CUT:
            acc += G[5, m] * exp_neg(t[m])
    return acc / (2.0 * math.pi)


@njit_serial
def vertex_density(vplanes, vofs, T, types, tj0, ti0, jlo, jhi, ilo, ihi, wx0, wx1, wy0, wy1,
                   gxw, gyw, c0, c1, qx, qy, f, var, sr2):  # pragma: no cover - compiled
    """Footprint-weighted point density at ``(qx, qy)`` of the dependent texels of the ``T x T``
    tiles ``ilo..ihi`` x ``jlo..jhi`` inside the window ``[wx0, wx1] x [wy0, wy1]`` (weights
    ``gxw``, ``gyw``), by grid vertex: each vertex's elements are the row of the vertex table
    (:func:`vertex_planes` ``vplanes``, offsets ``vofs``) of its configuration (``types`` from
    tile ``(ti0, tj0)``, a valid tiling); as Gaussians of ``brdf._row_gaussians``, cut at 6
    stds (:func:`gaussians_density`)."""
    nd = vofs.shape[0]
    G = np.empty((6, (jhi - jlo + 2) * (ihi - ilo + 2) * nd))
    fdx = np.empty(1)
    wx = np.empty(1)
    VX, VY, V00, V01, V10, V11 = (vplanes[0], vplanes[1], vplanes[2], vplanes[3], vplanes[4],
                                  vplanes[5])
    n = 0
    for j in range(jlo, jhi + 2):
        for i in range(ilo, ihi + 2):
            k = vertex_config(types[j - 1 - tj0, i - 1 - ti0], types[j - tj0, i - ti0])
            for e in range(nd):
                x = i * T + vofs[e, 0]
                y = j * T + vofs[e, 1]
                if not (wx0 <= x <= wx1 and wy0 <= y <= wy1):
                    continue
                fdx[0] = f * (c0 - (x + 0.5))
                wx[0] = gxw[x - wx0]
                _row_gaussians(V00[k], V01[k], V10[k], V11[k], VX[k], VY[k], 0, e, 1, fdx,
                               f * (c1 - (y + 0.5)), var, sr2, wx, gyw[y - wy0], G, n)
                n += 1
    return gaussians_density(G, n, qx, qy, np.empty(n))


@njit_serial
def dep_gaussian(tiles, types, jj, ii, nb5, gx, gy, cx, cy, f, var, tot2):  # pragma: no cover
    """:func:`_nb_gaussian` of a dependent texel ``(gx, gy)`` of the tile at ``types[jj,
    ii]``, its neighbours looked up by the table ``nb5 (5, 4)`` of
    :func:`dependent_neighbours` (same values, no integer division)."""
    mx, my, a, b, d = dep_element(tiles, types, jj, ii, nb5, gx, gy, cx, cy, f, var)
    dx = cx - (gx + 0.5)
    dy = cy - (gy + 0.5)
    return math.exp(-(dx * dx + dy * dy) / (2.0 * tot2)), mx, my, a, b, d


@njit_serial
def dep_element(tiles, types, jj, ii, nb5, gx, gy, cx, cy, f, var):  # pragma: no cover
    """:func:`dep_gaussian` without the footprint weight: the element's mean ``(mx, my)`` and
    positional covariance ``(a, b, d)``."""
    ty = types
    s00 = tiles[ty[jj + nb5[0, 0], ii + nb5[0, 1]], nb5[0, 2], nb5[0, 3], 0]
    s01 = tiles[ty[jj + nb5[0, 0], ii + nb5[0, 1]], nb5[0, 2], nb5[0, 3], 1]
    t1 = ty[jj + nb5[1, 0], ii + nb5[1, 1]]
    t2 = ty[jj + nb5[2, 0], ii + nb5[2, 1]]
    t3 = ty[jj + nb5[3, 0], ii + nb5[3, 1]]
    t4 = ty[jj + nb5[4, 0], ii + nb5[4, 1]]
    jx0 = 0.5 * (tiles[t1, nb5[1, 2], nb5[1, 3], 0] - tiles[t2, nb5[2, 2], nb5[2, 3], 0])
    jx1 = 0.5 * (tiles[t1, nb5[1, 2], nb5[1, 3], 1] - tiles[t2, nb5[2, 2], nb5[2, 3], 1])
    jy0 = 0.5 * (tiles[t3, nb5[3, 2], nb5[3, 3], 0] - tiles[t4, nb5[4, 2], nb5[4, 3], 0])
    jy1 = 0.5 * (tiles[t3, nb5[3, 2], nb5[3, 3], 1] - tiles[t4, nb5[4, 2], nb5[4, 3], 1])
    dx = cx - (gx + 0.5)
    dy = cy - (gy + 0.5)
    mx = s00 + f * (jx0 * dx + jy0 * dy)
    my = s01 + f * (jx1 * dx + jy1 * dy)
    a, b, d = element_covariance(jx0, jy0, jx1, jy1, var, 0.0)
    return mx, my, a, b, d


@njit_serial
def _nb_texel(tiles, types, i0, j0, gx, gy, cx, cy, f, var, tot2, sr, lo, h, R, trunc, iy,
              ix):  # pragma: no cover - compiled
    """Unnormalised pixel value of texel ``(gx, gy)``'s element (:func:`_nb_gaussian`)."""
    w, mx, my, a, b, d = _nb_gaussian(tiles, types, i0, j0, gx, gy, cx, cy, f, var, tot2)
    return _nb_element(mx, my, a, b, d, w, sr, lo, h, R, trunc, iy, ix)


@njit_serial
def _nb_texel_point(tiles, types, i0, j0, gx, gy, cx, cy, f, var, tot2, sr, trunc, qx,
                    qy):  # pragma: no cover - compiled
    """Unnormalised density at ``(qx, qy)`` of texel ``(gx, gy)``'s element (as
    ``pndf._pndf_points``: covariance ``sr^2 I + var J J^T``, cut beyond ``2 trunc`` stds)."""
    w, mx, my, a, b, d = _nb_gaussian(tiles, types, i0, j0, gx, gy, cx, cy, f, var, tot2)
    sr2 = sr * sr
    return w * element_density(qx - mx, qy - my, a + sr2, b, d + sr2, 8.0 * trunc * trunc)


@njit_serial
def _nb_density(ex, ey, j00, j01, j10, j11, var, sr, trunc):  # pragma: no cover - compiled
    """``N((ex, ey); 0, sr^2 I + var J J^T)``, 0 beyond ``2 trunc`` stds (``pndf._pndf_points``;
    ``J = [[j00, j01], [j10, j11]]``)."""
    a, b, d = element_covariance(j00, j01, j10, j11, var, sr * sr)
    return element_density(ex, ey, a, b, d, 8.0 * trunc * trunc)


def shares_args(wn: TiledNDF) -> tuple:
    """``(mbasis (3, T), msat (R + 1, R + 1, 16 n_m) float32)`` of the kernels' tile-type
    shares regime: the moment tables with the types and moments of a position flattened
    (``n_m`` 5, or 0 without moment tables: shares alone)."""
    msat = wn.moment_sat
    if msat is None:
        msat = np.zeros((1, 1, 16, 0), np.float32)
    return moment_basis(wn.wang.size), msat.reshape(msat.shape[0], msat.shape[1], -1)


@njit_serial
def shares_moments(wx0, wx1, wy0, wy1, gxw, gyw, T, mbasis, seed, index,
                   n_mom):  # pragma: no cover - compiled; _type_moments
    """``(16, n_mom)`` :func:`type_moments` of a footprint from its weights ``gxw``, ``gyw``
    along the texel rows ``wx0 .. wx1`` and columns ``wy0 .. wy1`` (first ``n_mom`` pairs):
    the in-tile moments per tile column and row (separable), then summed by tile type."""
    i0, j0 = wx0 // T, wy0 // T
    wcol = np.zeros((wx1 // T - i0 + 1, 3))
    wrow = np.zeros((wy1 // T - j0 + 1, 3))
    types = _nb_types(i0, wx1 // T, j0, wy1 // T, seed, index)
    segment_moments(gxw, wx0, T, mbasis, wcol)
    segment_moments(gyw, wy0, T, mbasis, wrow)
    sx = 0.0
    for a in range(wcol.shape[0]):
        sx += wcol[a, 0]
    sy = 0.0
    for b in range(wrow.shape[0]):
        sy += wrow[b, 0]
    mom = np.zeros((16, n_mom))
    for b in range(wrow.shape[0]):
        r0, r1, r2 = wrow[b, 0], wrow[b, 1], wrow[b, 2]
        for a in range(wcol.shape[0]):
            t = types[b, a]
            c0 = wcol[a, 0]
            mom[t, 0] += r0 * c0
            if n_mom > 1:  # MOMENT_PAIRS, unrolled
                mom[t, 1] += r0 * wcol[a, 1]
                mom[t, 2] += r1 * c0
                mom[t, 3] += r0 * wcol[a, 2]
                mom[t, 4] += r1 * wcol[a, 1]
                mom[t, 5] += r2 * c0
    inv = 1.0 / (sx * sy)
    for t in range(16):
        for k in range(n_mom):
            mom[t, k] *= inv
    return mom


@njit_serial
def weighted_dot(S, w, y, x):  # pragma: no cover - compiled
    """``sum_k w[k] S[y, x, k]`` (the float32 tables' entries times float64 weights before
    any difference between positions is taken: under fast-math those could be float32)."""
    v = 0.0
    for k in range(w.shape[0]):
        v += w[k] * S[y, x, k]
    return v


@njit_serial
def moment_weights(mom):  # pragma: no cover - compiled
    """``(16 n_m,)`` the moments ``mom[:, 1:]`` of :func:`shares_moments` in the flattened
    tables' order (type-major)."""
    n_m = mom.shape[1] - 1
    w = np.empty(16 * n_m)
    for t in range(16):
        for k in range(n_m):
            w[t * n_m + k] = mom[t, k + 1]
    return w


@njit_serial
def shares_means(means_px, mom, y, x):  # pragma: no cover - compiled
    """``sum_t mom[t, 0] tile_means[t, y, x]``: the plain shares' part of a pixel
    (``means_px``: :attr:`TiledNDF.means_px`)."""
    v = 0.0
    for t in range(16):
        v += mom[t, 0] * means_px[y, x, t]
    return v


@njit_serial
def shares_pixel(means_px, msat, mom, wm, y, x):  # pragma: no cover - compiled
    """The tile-type shares regime's NDF at pixel ``(y, x)`` before the clamp at 0:
    ``sum_t mom[t, 0] tile_means[t] + sum_k mom[t, k + 1] E_tk`` (the moment images' pixels
    from their flattened tables ``msat`` weighted by ``wm``, :func:`moment_weights`;
    :func:`_shares_values`)."""
    v = shares_means(means_px, mom, y, x)
    if wm.shape[0]:
        v += ((weighted_dot(msat, wm, y + 1, x + 1) - weighted_dot(msat, wm, y, x + 1))
              - (weighted_dot(msat, wm, y + 1, x) - weighted_dot(msat, wm, y, x)))
    return v


@njit_parallel
def _points_kernel(gstart, cx, cy, sp, py0, px0, wya, wxa, qx, qy, point_sr, tiles, el_s, el_J,
                   depmask, seed, index, images, Fa, Fb, wsc, cq, bidx, meta, offs, goff, crops,
                   block, k0, st0, sigma0, dep, depn, planes, vplanes, vofs, means_px, mean,
                   mbasis, msat, sr, lo, h, min_sigma, wide_sigma, uniform_sigma, q_min,
                   tap_trunc, trunc, sh,
                   has_vertex, vFa, vFb, vwsc, vcq, vbidx, vmeta, voffs, vgoff, vk0, vcrops,
                   valid, out):  # pragma: no cover - compiled
    """``out[q]``: the footprint NDF ``(cx, cy, sp)[q]`` (queries ``gstart[g] ..
    gstart[g + 1] - 1`` share one footprint: on the implicit tiling below ``min_sigma`` its
    elements are formed once for them) at ``sum_ab wya[q, a] wxa[q, b]`` times
    pixel ``(py0 + a, px0 + b)`` (one pixel of weight 1: :func:`ndf`; 2 x 2: bilinear between
    pixel centres); with ``point_sr > 0`` the texels not in the pyramids (below ``min_sigma``
    all of them, above it the dependent texels) add their point densities at ``(qx, qy)[q]``
    with intrinsic roughness ``point_sr`` instead of pixel values. ``block > 0``: compressed
    levels, the arrays of a :class:`prefilter.glints.wang_query.TilePack` (``images``
    unused), each tap's code rows summed per CP group (:func:`prefilter.glints.wang_query.
    pack_point`); ``crops (L,)``: centres per axis per level. ``el_s, el_J``:
    :func:`tile_elements`; ``depmask (T, T)``: :func:`dependent_texels`. On the implicit tiling
    (``index`` empty) the point densities come from ``planes`` (:func:`tile_planes`) and the
    vertex table ``vplanes``, ``vofs`` (:func:`vertex_planes`), cut at 6 stds; with an explicit
    map, from neighbour lookups, cut at ``2 trunc`` stds. ``has_vertex``: on the implicit
    tiling, above ``min_sigma`` and without ``point_sr`` the dependent texels' pixel values
    come from the vertex pyramids (the pack arrays ``vFa`` ..., their crops from ``vk0`` of
    ``vcrops`` centres, :func:`vertex_window`) instead of pixel integrals of their elements.
    ``valid``: the tiling is valid (implicit, or an explicit map that
    :func:`prefilter.glints.wang.is_valid_tiling`): what "the implicit tiling" above needs."""
    T = tiles.shape[1]
    R = mean.shape[0]
    L = len(images)
    rank = 1
    for g in range(meta.shape[0]):
        rank = max(rank, meta[g, 0])
    for gq in prange(gstart.shape[0] - 1):
        q0, q1 = gstart[gq], gstart[gq + 1]
        s = sp[q0]
        if point_sr > 0.0 and valid and s < min_sigma and q1 - q0 > 1:
            # several points of one footprint on the implicit tiling below min_sigma: its
            # elements' Gaussians formed once (glints-direct's K-point kernels)
            c0, c1 = cx[q0], cy[q0]
            tot2, rad, wx0, wx1, wy0, wy1 = footprint_rows(c0, c1, s, sh, trunc)
            gxw = gauss_row(c0, wx0, wx1, tot2)
            gyw = gauss_row(c1, wy0, wy1, tot2)
            ti0, tj0 = wx0 // T - 1, wy0 // T - 1
            types = _nb_types(ti0, wx1 // T + 1, tj0, wy1 // T + 1, seed, index)
            G = direct_gaussians(planes, vplanes, vofs, T, types, ti0, tj0, wx0, wx1, wy0, wy1,
                                 gxw, gyw, c0, c1, sh * sh / tot2, s * s * sh * sh / tot2,
                                 point_sr * point_sr)
            tt = np.empty(G.shape[1])
            nrm = gxw.sum() * gyw.sum()
            for q in range(q0, q1):
                out[q] = gaussians_density(G, G.shape[1], qx[q], qy[q], tt) / nrm
            continue
        for q in range(q0, q1):
            out[q] = 0.0
            cwp = np.empty((16, rank), np.float32)  # per tile type: its taps' summed code rows
            gsp = np.empty(16, np.int64)
            slot_of = np.empty(16, np.int64)
            c0, c1, s = cx[q], cy[q], sp[q]
            # the corners with a weight: pixel rows, columns, weights (at most 4)
            cy_ = np.empty(4, np.int64)
            cx_ = np.empty(4, np.int64)
            cw = np.empty(4)
            nc = 0
            for a in range(2):
                for b in range(2):
                    wab = wya[q, a] * wxa[q, b]
                    if wab != 0.0:
                        cy_[nc], cx_[nc], cw[nc] = py0[q] + a, px0[q] + b, wab
                        nc += 1
            point = s < min_sigma and point_sr > 0.0
            if nc == 0 and not point_sr > 0.0:
                continue
            if s >= uniform_sigma:
                acc = 0.0
                for k in range(nc):
                    acc += cw[k] * mean[cy_[k], cx_[k]]
                out[q] = acc
                continue
            tot2, rad, wx0, wx1, wy0, wy1 = footprint_rows(c0, c1, s, sh, trunc)
            gxw = gauss_row(c0, wx0, wx1, tot2)
            gyw = gauss_row(c1, wy0, wy1, tot2)
            sx = 0.0
            for x in range(gxw.shape[0]):
                sx += gxw[x]
            sy = 0.0
            for y in range(gyw.shape[0]):
                sy += gyw[y]
            if s >= wide_sigma:  # tile-type shares and in-tile moments, per type
                mom = shares_moments(wx0, wx1, wy0, wy1, gxw, gyw, T, mbasis, seed,
                                     index, 1 + msat.shape[2] // 16)
                wm = moment_weights(mom)
                acc = 0.0
                if nc == 4 and wm.shape[0]:
                    # a 2 x 2 block of pixels: the 3 x 3 table positions of its corners once
                    y0, x0 = cy_[0], cx_[0]
                    dots = np.empty((3, 3))
                    for i in range(3):
                        for j in range(3):
                            dots[i, j] = weighted_dot(msat, wm, y0 + i, x0 + j)
                    for k in range(4):
                        i, j = cy_[k] - y0, cx_[k] - x0
                        v = (shares_means(means_px, mom, cy_[k], cx_[k])
                             + ((dots[i + 1, j + 1] - dots[i, j + 1])
                                - (dots[i + 1, j] - dots[i, j])))
                        acc += cw[k] * max(v, 0.0)
                else:
                    for k in range(nc):
                        acc += cw[k] * max(shares_pixel(means_px, msat, mom, wm, cy_[k],
                                                        cx_[k]), 0.0)
                out[q] = acc
                continue
            f = sh * sh / tot2
            var = s * s * sh * sh / tot2
            if s < min_sigma:  # direct P-NDF
                acc = 0.0
                ti0, tj0 = wx0 // T - 1, wy0 // T - 1
                types = _nb_types(ti0, wx1 // T + 1, tj0, wy1 // T + 1, seed, index)
                if point and valid:
                    # the implicit tiling: the window's elements as Gaussians row segment by row
                    # segment from the tile planes, the dependent texels from the vertex table
                    G = direct_gaussians(planes, vplanes, vofs, T, types, ti0, tj0, wx0, wx1, wy0,
                                         wy1, gxw, gyw, c0, c1, f, var, point_sr * point_sr)
                    out[q] = gaussians_density(G, G.shape[1], qx[q], qy[q],
                                               np.empty(G.shape[1])) / (sx * sy)
                    continue
                if point:
                    # the tiles' own elements (exact away from the dependent texels, which look
                    # up their neighbours) and separable weights: a few flops and one exp a texel
                    wcx = gxw
                    for y in range(wy0, wy1 + 1):
                        dy = c1 - (y + 0.5)
                        wr = gyw[y - wy0]
                        ty = y // T
                        ry = y - ty * T
                        # texels by tile segments of the row: no integer division per texel
                        for i in range(wx0 // T, wx1 // T + 1):
                            t = types[ty - tj0, i - ti0]
                            for x in range(max(wx0, i * T), min(wx1, i * T + T - 1) + 1):
                                rx = x - i * T
                                if depmask[ry, rx]:
                                    acc += _nb_texel_point(tiles, types, ti0, tj0, x, y, c0, c1, f,
                                                           var, tot2, point_sr, trunc, qx[q], qy[q])
                                    continue
                                dx = c0 - (x + 0.5)
                                j00, j01 = el_J[t, ry, rx, 0, 0], el_J[t, ry, rx, 0, 1]
                                j10, j11 = el_J[t, ry, rx, 1, 0], el_J[t, ry, rx, 1, 1]
                                ex = qx[q] - el_s[t, ry, rx, 0] - f * (j00 * dx + j01 * dy)
                                ey = qy[q] - el_s[t, ry, rx, 1] - f * (j10 * dx + j11 * dy)
                                acc += wr * wcx[x - wx0] * _nb_density(ex, ey, j00, j01, j10, j11,
                                                                       var, point_sr, trunc)
                    out[q] = acc / (sx * sy)
                    continue
                for y in range(wy0, wy1 + 1):
                    for x in range(wx0, wx1 + 1):
                        for k in range(nc):
                            acc += cw[k] * _nb_texel(tiles, types, ti0, tj0, x, y, c0, c1, f, var,
                                                     tot2, sr, lo, h, R, trunc, cy_[k], cx_[k])
                out[q] = acc / (sx * sy * h * h)
                continue
            (m, n, ti0, tj0, types, jlo, jhi, ilo, ihi, wyt, wxt, kyl, kyh, kxl,
             kxh) = level_window(s, c0, c1, sigma0, st0, L, q_min, tap_trunc, crops, k0, rad, T,
                                 seed, index)
            acc = 0.0
            if block > 0:
                acc = pack_point(Fa, Fb, wsc, cq, bidx, meta, offs[m], goff[m], n, block, types,
                                 jlo - tj0, ilo - ti0, wyt, wxt, kyl, kyh, kxl, kxh, py0[q],
                                 wya[q, 0], wya[q, 1], px0[q], wxa[q, 0], wxa[q, 1], cwp, gsp,
                                 slot_of)
            else:
                img = images[m]
                for jj in range(jhi - jlo + 1):
                    for ii in range(ihi - ilo + 1):
                        t = types[jlo + jj - tj0, ilo + ii - ti0]
                        for ky in range(kyl[jj], kyh[jj] + 1):
                            for kx in range(kxl[ii], kxh[ii] + 1):
                                v = 0.0
                                for k in range(nc):
                                    v += cw[k] * img[t, ky, kx, cy_[k], cx_[k]]
                                acc += wyt[jj, ky] * wxt[ii, kx] * v
            if has_vertex and valid and not point_sr > 0.0:
                # the dependent texels' pixel values from their vertex pyramids (a valid tiling;
                # their point densities below, as cheap and exact)
                vn = vcrops[m]
                vt, vwy, vwx, vkyl, vkyh, vkxl, vkxh = vertex_window(
                    s, c0, c1, m, vn, sigma0, st0, tap_trunc, vk0[m], rad, T, types, ti0, tj0)
                out[q] = acc + pack_point(vFa, vFb, vwsc, vcq, vbidx, vmeta, voffs[m], vgoff[m],
                                          vn, block, vt, 0, 0, vwy, vwx, vkyl, vkyh, vkxl, vkxh,
                                          py0[q], wya[q, 0], wya[q, 1], px0[q], wxa[q, 0],
                                          wxa[q, 1], cwp, gsp, slot_of)
                continue
            dsum = 0.0
            psum = 0.0
            if point_sr > 0.0 and valid:
                # the dependent texels by grid vertex, no neighbour lookups (the implicit tiling is
                # valid)
                out[q] = acc + vertex_density(vplanes, vofs, T, types, tj0, ti0, jlo, jhi, ilo, ihi,
                                              wx0, wx1, wy0, wy1, gxw, gyw, c0, c1, qx[q], qy[q], f,
                                              var, point_sr * point_sr) / (sx * sy)
                continue
            for j in range(jlo, jhi + 1):
                for i in range(ilo, ihi + 1):
                    for e in range(dep.shape[0]):
                        x = i * T + dep[e, 1]
                        y = j * T + dep[e, 0]
                        if not (wx0 <= x <= wx1 and wy0 <= y <= wy1):
                            continue
                        if point_sr > 0.0:
                            # what the bilinear lookup of their pixel averages approximates, exactly
                            # and at a fraction of the cost (no pixel integrals, one element)
                            mx, my, a_, b_, d_ = dep_element(tiles, types, j - tj0, i - ti0,
                                                             depn[e], x, y, c0, c1, f, var)
                            w = gxw[x - wx0] * gyw[y - wy0]  # the footprint weight, separable
                            sr2 = point_sr * point_sr
                            psum += w * element_density(qx[q] - mx, qy[q] - my, a_ + sr2, b_,
                                                        d_ + sr2, 8.0 * trunc * trunc)
                            continue
                        for k in range(nc):
                            dsum += cw[k] * _nb_texel(tiles, types, ti0, tj0, x, y, c0, c1, f, var,
                                                      tot2, sr, lo, h, R, trunc, cy_[k], cx_[k])
            out[q] = acc + dsum / (sx * sy * h * h) + psum / (sx * sy)


@njit_serial
def _taps_kernel(f, R, bilinear, p, w):  # pragma: no cover - compiled
    for n in range(f.shape[0]):
        for a in range(2):
            p[n, a], w[n, a, 0], w[n, a, 1] = pixel_taps(f[n, a], R, bilinear)


def _pixel_taps(wn: TiledNDF, q, bilinear: bool):
    """First pixel row / column ``(N,)`` and the weights ``(N, 2)`` of it and the next, per
    axis (:func:`prefilter.glints._qkernels.pixel_taps`, the glints map's lookup): the pixel
    holding ``q (N, 2)`` (weight 1, 0 outside the support), or bilinear between pixel centres
    (pixels outside the support weigh 0)."""
    R, S = wn.resolution, wn.support
    f = np.ascontiguousarray((q + S) / (2.0 * S / R), dtype=np.float64)
    p = np.empty(f.shape, np.int64)
    w = np.empty(f.shape + (2,))
    _taps_kernel(f, R, bool(bilinear), p, w)
    # x is axis 0 of q, the image's column
    return p[:, 1], p[:, 0], np.ascontiguousarray(w[:, 1]), np.ascontiguousarray(w[:, 0])


def ndf_points(wn: TiledNDF, center, sigma_p, s, *, index=None, bilinear: bool = False,
               point_roughness: float | None = None, direct: bool = False) -> np.ndarray:
    """Batched :func:`ndf`: NDF values ``(...)`` of footprints ``center (..., 2)``,
    ``sigma_p (...)`` at ``s (..., 2)`` (broadcast together), one Numba kernel for all regimes,
    uncompressed or CP-compressed pyramids (compressed: each tap reads its ``C`` row, ``rank``
    numbers, against the query pixel's ``A`` and ``B`` entries). Same arithmetic as
    :func:`ndf`, without Python per footprint. Consecutive queries of one footprint (equal
    centre and ``sigma_p``, e.g. a pixel's light samples) are taken together: below
    ``min_sigma`` on the implicit tiling its elements are formed once for all of them.

    ``bilinear``: the stored pixel averages interpolated between pixel centres (pixels outside
    the support weigh 0); the texels computed at query time (below ``wn.min_sigma`` all, the
    direct P-NDF's point value as ``pndf.pndf``; above it the dependent texels) as point
    densities with intrinsic roughness ``point_roughness`` (default
    ``wn.intrinsic_roughness``). Bake with
    :func:`prefilter.glints.bake.bilinear_bake_roughness` of it so that the interpolation's blur
    restores it (as the ``glints`` render cache does).

    ``direct``: the direct P-NDF of the tiling at every footprint (no pyramid, share or expected
    tiling regime): the reference the regimes approximate, ``glints-direct``'s NDF on the
    assembled tiling; its cost grows with the footprint's texels."""
    if not isinstance(wn, TiledNDF):
        raise PrefilterError(f"wn: expected a TiledNDF (bake_tiles), got {type(wn).__name__}")
    c = as_float_array(center, "center", ndim_min=1, last_dim=2)
    sp = as_sigma_p(sigma_p)
    q = as_float_array(s, "s", ndim_min=1, last_dim=2)
    shape = broadcast_batch(center=c.shape[:-1], sigma_p=sp.shape, s=q.shape[:-1])
    idx = _as_index(index)
    idx = np.zeros((0, 0), np.int64) if idx is None else np.ascontiguousarray(idx, np.int64)
    psr = 0.0
    if bilinear:
        psr = as_intrinsic_roughness(wn.intrinsic_roughness if point_roughness is None
                                     else point_roughness)
    c = kernel_array(c, shape + (2,)).reshape(-1, 2)
    sp = kernel_array(sp, shape).reshape(-1)
    q = kernel_array(q, shape + (2,)).reshape(-1, 2)
    py0, px0, wy, wx = _pixel_taps(wn, q, bool(bilinear))
    out = np.empty(sp.shape[0])
    cc = np.ascontiguousarray
    images, pk = _kernel_levels(wn)
    el_s, el_J, depmask = _kernel_elements(wn)
    _, vplanes, vofs = _vertex_tables(wn)
    valid = _valid(idx)
    if not valid:
        # an explicit map may put mismatched edges side by side (a block of the implicit tiling
        # wraps so): the border texels look up their actual neighbours
        depmask = depmask.copy()
        depmask[[0, -1]] = True
        depmask[:, [0, -1]] = True
    # runs of queries of one footprint (the renderer's light samples of a pixel)
    new = np.ones(len(sp), bool)
    new[1:] = (c[1:, 0] != c[:-1, 0]) | (c[1:, 1] != c[:-1, 1]) | (sp[1:] != sp[:-1])
    gstart = np.append(np.flatnonzero(new), len(sp)).astype(np.int64)
    serial(_points_kernel, len(out))(
        gstart, cc(c[:, 0]), cc(c[:, 1]), sp, py0, px0, wy, wx, cc(q[:, 0]), cc(q[:, 1]), psr,
        cc(wn.wang.tiles[..., :2]), el_s, el_J, depmask, np.uint64(wn.wang.seed), idx, images,
        pk.Fa, pk.Fb, pk.wsc, pk.cq, pk.bidx, pk.meta, pk.offs, pk.goff,
        np.array([wn.crop(lv) for lv in range(wn.n_levels)], np.int64),
        int(wn.block), np.asarray(wn.k0, np.int64), float(wn.stride0), wn.sigma0,
        cc(wn.dependent, dtype=np.int64), dependent_neighbours(wn), tile_planes(wn),
        vplanes, vofs, wn.means_px, wn.mean, *shares_args(wn), wn.intrinsic_roughness,
        -wn.support, 2.0 * wn.support / wn.resolution,
        *((math.inf,) * 3 if direct else (wn.min_sigma, wn.wide_sigma, wn.uniform_sigma)),
        _Q_MIN, _TAP_TRUNCATION, TRUNCATION, SIGMA_H, *vertex_args(wn)[:11], valid, out)
    return out.reshape(shape)


def _valid(idx: np.ndarray) -> bool:
    """Whether the kernels' explicit map ``idx`` (empty: the implicit tiling) is a valid tiling
    (:func:`prefilter.glints.wang.is_valid_tiling`: then its dependent texels are those of the
    vertex table, and its other border texels' expected neighbours exact)."""
    return idx.size == 0 or is_valid_tiling(idx)


def vertex_args(wn: TiledNDF) -> tuple:
    """``(has_vertex, Fa, Fb, wsc, cq, bidx, meta, offs, goff, k0, crops, Pa, Pb)`` of ``wn``'s
    vertex pyramids for the kernels (an empty pack of the tiles' dtypes without them)."""
    vp = wn.vertex_pack if wn.block else None
    p = vp if vp is not None else empty_pack(wn.n_levels, like=wn.pack)
    k0 = np.asarray(wn.vertex_k0 if vp is not None else (0,) * wn.n_levels, np.int64)
    return (vp is not None, p.Fa, p.Fb, p.wsc, p.cq, p.bidx, p.meta, p.offs, p.goff, k0,
            np.asarray(p.crops, np.int64), p.Pa, p.Pb)


_ELEMENTS: dict = {}
_PLANES: dict = {}
_VERTICES: dict = {}


def tile_planes(wn: TiledNDF) -> np.ndarray:
    """``(6, 16, T, T)`` float64: the tiles' elements (:func:`tile_elements`) as the planes
    ``s_x, s_y, j00, j01, j10, j11`` of ``brdf._row_gaussians`` (cached with them)."""
    el_s, el_J, _ = _kernel_elements(wn)
    hit = _PLANES.get(id(wn.wang))
    if hit is None or hit[0] is not el_s:
        pl = np.stack([el_s[..., 0], el_s[..., 1], el_J[..., 0, 0], el_J[..., 0, 1],
                       el_J[..., 1, 0], el_J[..., 1, 1]])
        hit = _PLANES[id(wn.wang)] = (el_s, np.ascontiguousarray(pl))
    return hit[1]


def vertex_planes(vel: np.ndarray) -> np.ndarray:
    """``(6, 16, 1, n_dep)`` float64: :func:`vertex_elements`' slopes and Jacobians as planes
    of one row per configuration (``brdf._row_gaussians``' layout)."""
    return np.ascontiguousarray(np.moveaxis(vel[..., 2:], -1, 0)[:, :, None, :])


def _vertex_tables(wn: TiledNDF):
    """:func:`vertex_elements`, its :func:`vertex_planes` and the texels' integer offsets
    ``(n_dep, 2)`` from their vertex, cached per tile set and dependent texels (every frame
    queries the same tiles)."""
    key = (id(wn.wang), np.asarray(wn.dependent, np.int64).tobytes())
    hit = _VERTICES.get(key)
    if hit is None or hit[0] is not wn.wang:
        vel = vertex_elements(wn)
        hit = _VERTICES[key] = (wn.wang, vel, vertex_planes(vel),
                                np.ascontiguousarray(vel[0, :, :2], dtype=np.int64))
    return hit[1:]


def _kernel_elements(wn: TiledNDF):
    """:func:`tile_elements` and the dependent-texel mask ``(T, T)`` of ``wn``'s tiles (cached
    per tile set: the renderer queries the same tiles every frame)."""
    key = id(wn.wang)
    hit = _ELEMENTS.get(key)
    if hit is None or hit[0] is not wn.wang:
        el_s, el_J = tile_elements(wn.wang)
        hit = _ELEMENTS[key] = (wn.wang, np.ascontiguousarray(el_s), np.ascontiguousarray(el_J))
    T = wn.wang.size
    dep = np.zeros((T, T), np.bool_)
    dep[wn.dependent[:, 0], wn.dependent[:, 1]] = True
    return hit[1], hit[2], dep


def _kernel_levels(wn: TiledNDF):
    """The levels as :func:`_points_kernel` takes them: dense float32 images (1-element
    placeholders when compressed) and the :class:`~prefilter.glints.wang_query.TilePack` (empty
    when uncompressed; one compiled kernel serves both per factor dtype)."""
    L = wn.n_levels
    if wn.block:
        return (np.zeros((1, 1, 1, 1, 1), np.float32),) * L, wn.pack
    return tuple(np.ascontiguousarray(a, np.float32) for a in wn.images), wn.pack
