"""Adaptive model selection (paper IV-B): merge redundant components of a mixture.

Components are classified by shape: a flat component (smallest variance under ``flat_ratio`` of
the middle one: a patch of floor, wall or table) by the direction of its smallest axis, the plane
normal, quantised to 13 directions; the others form one volumetric class. Within a class, only
components whose means are closer than ``max_distance`` are compared, and pairs whose symmetric
Kullback-Leibler divergence is below ``kl_threshold`` merge, most similar first, by exact moment
matching (π = Σπₖ, μ = Σπₖμₖ/π, Σ = Σπₖ(Σₖ + (μₖ−μ)(μₖ−μ)ᵀ)/π). Merged components are
re-classified and may merge again. The mixture's total mass, mean and covariance are preserved
exactly. Cost: O(K log K) for well-spread components (a spatial hash finds the neighbours).
"""

from __future__ import annotations

import numpy as np

from gmmap import _core
from gmmap.math.gmm import Gmm
from gmmap.options import SelectOptions


def select_components(
    gmm: Gmm, options: SelectOptions | None = None, *, return_labels: bool = False
) -> Gmm | tuple[Gmm, np.ndarray]:
    """The mixture with redundant components merged.

    With ``return_labels``, also the index of the output component that absorbed each input
    component. Unmerged components keep their order; merged ones follow.
    """
    o = options or SelectOptions()
    (w, m, c), labels = _core.select_components(
        gmm.weights, gmm.means, gmm.covariances, o.flat_ratio, o.max_distance, o.kl_threshold
    )
    out = Gmm(w, m, c)
    return (out, labels) if return_labels else out
