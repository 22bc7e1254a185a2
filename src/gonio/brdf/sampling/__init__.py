"""Sampling: every way gonio turns uniform numbers into directions, points and table cells.

Randomness is always passed in (``u`` in [0, 1)^d); nothing here draws its own random numbers.
Each concept lives in one module:

=====================================================  ============================================
concept                                                module
=====================================================  ============================================
1-D/2-D piecewise-constant distributions (CDF           :mod:`~gonio.brdf.sampling.distributions`
inversion), alias tables, counter-based uniforms,
traced rejection sampling
square -> disk / hemisphere / cosine-power warps and    :mod:`~gonio.brdf.sampling.warps`
their densities
continuous marginal/conditional 2-D warp over a         :mod:`~gonio.brdf.sampling.marginal2d`
bilinear grid with parameters (RGL tensor files)
quadtree warp of a 2-D piecewise-constant density       :mod:`~gonio.brdf.sampling.quadtree`
(environment lights)
sample points: Sobol' integers and the rank-1 lattice   :mod:`~gonio.brdf.sampling.points`
sequence the renderer uses
sampling a tabulated BRDF (inversion, alias)            :mod:`~gonio.brdf.sampling.table`
the outgoing-direction buckets and incident cells of    :mod:`~gonio.brdf.sampling.table_buckets`
table sampling
exact rejection sampling of a table (interval bounds)   :mod:`~gonio.brdf.sampling.table_rejection`
=====================================================  ============================================

Like the rest of :mod:`gonio.brdf`, this package imports nothing else of gonio except
:mod:`gonio.errors`.
"""

from gonio.brdf.sampling import marginal2d, points, warps
from gonio.brdf.sampling.distributions import (
    AliasTable,
    Distribution1D,
    Distribution2D,
)
from gonio.brdf.sampling.marginal2d import Marginal2D
from gonio.brdf.sampling.quadtree import HierarchicalWarp2D
from gonio.brdf.sampling.table import TableSampler
from gonio.brdf.sampling.table_rejection import TableRejection

__all__ = [
    "AliasTable",
    "Distribution1D",
    "Distribution2D",
    "HierarchicalWarp2D",
    "Marginal2D",
    "TableRejection",
    "TableSampler",
    "marginal2d",
    "points",
    "warps",
]
