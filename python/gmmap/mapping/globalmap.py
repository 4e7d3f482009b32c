"""The merged global map of a connected group of robots.

Every submap of the group is moved into the reference frame (the reference robot's map frame)
by its optimised anchor pose, covariances rotated in full; each submap's weights are scaled by
its share of the group's points, so a well-observed submap weighs more; then the same model
selection as inside a submap merges the components that several submaps contribute for one
surface.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from gmmap.errors import InvalidInputError
from gmmap.mapping.submap import Submap, concatenate
from gmmap.math.gmm import Gmm
from gmmap.math.points import as_points
from gmmap.math.select import SelectOptions, select_components

# A point within this many standard deviations (Mahalanobis) of a component is occupied.
OCCUPIED_SIGMAS = 2.0


@dataclass
class GlobalMap:
    """A group's map: ``gmm`` and the optimised anchor positions per robot, in the reference
    robot's map frame."""

    reference: str
    gmm: Gmm
    trajectories: dict[str, np.ndarray] = field(default_factory=dict)
    n_points: int = 0

    def occupancy(self, x: object) -> np.ndarray:
        """exp(−d²/2) of the smallest Mahalanobis distance d to any component: 1 on a
        component's mean, 0.14 at two standard deviations, 0 far from every surface."""
        pts = as_points(x, "x")
        precision = np.linalg.inv(self.gmm.covariances)
        best = np.full(len(pts), np.inf)
        for start in range(0, len(pts), 4096):
            d = pts[start : start + 4096, None, :] - self.gmm.means[None]
            m = np.einsum("nki,kij,nkj->nk", d, precision, d)
            best[start : start + 4096] = m.min(axis=1)
        return np.exp(-0.5 * best)

    def is_occupied(self, x: object, sigmas: float = OCCUPIED_SIGMAS) -> np.ndarray:
        return self.occupancy(x) >= math.exp(-0.5 * sigmas**2)

    def is_free(self, x: object, sigmas: float = OCCUPIED_SIGMAS) -> np.ndarray:
        return ~self.is_occupied(x, sigmas)

    def sample(self, n: int, seed: int = 0) -> np.ndarray:
        return self.gmm.sample(n, seed)

    def save(self, path: str | os.PathLike) -> None:
        """The project's GMM file (``Gmm.load`` reads it)."""
        self.gmm.save(path)

    def save_png(
        self,
        path: str | os.PathLike,
        z_band: tuple[float, float] | None = None,
        resolution: float = 0.05,
        n: int = 400_000,
    ) -> None:
        """Top-down density (log scale) of the map between heights ``z_band`` (reference
        frame; default: everything), with each robot's trajectory of anchors."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        pts = self.sample(n)
        if z_band is not None:
            pts = pts[(pts[:, 2] >= z_band[0]) & (pts[:, 2] <= z_band[1])]
        lo, hi = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
        bins = np.maximum(1, np.ceil((hi - lo) / resolution)).astype(int)
        extent = [(lo[0], hi[0]), (lo[1], hi[1])]
        hist, xe, ye = np.histogram2d(pts[:, 0], pts[:, 1], bins=bins, range=extent)
        fig, ax = plt.subplots(figsize=(8, 8 * bins[1] / max(bins[0], 1) + 0.5))
        ax.imshow(
            np.log1p(hist.T), origin="lower", extent=(xe[0], xe[-1], ye[0], ye[-1]), cmap="Greys"
        )
        for name, traj in self.trajectories.items():
            ax.plot(traj[:, 0], traj[:, 1], marker=".", lw=1.5, label=name)
        ax.set(xlabel="x (m)", ylabel="y (m)", title=f"global map ({self.reference}'s frame)")
        ax.set_aspect("equal")
        if self.trajectories:
            ax.legend(loc="upper right", fontsize="small")
        fig.savefig(path, dpi=110, bbox_inches="tight")
        plt.close(fig)


def build_global_map(
    submaps: Sequence[Submap],
    poses: Mapping[tuple[str, int], np.ndarray],
    reference: str,
    selection: SelectOptions | None = None,
) -> GlobalMap:
    """Merges ``submaps`` whose optimised anchor poses (reference frame) are in ``poses``;
    submaps without a pose (another group) are left out."""
    placed = [s for s in submaps if (s.robot, s.seq) in poses]
    if not placed:
        raise InvalidInputError("no submap has an optimised pose: nothing to merge")
    moved = [s.gmm.transform(poses[(s.robot, s.seq)]) for s in placed]
    counts = [max(s.n_points, 1) for s in placed]
    merged = select_components(concatenate(moved, counts), selection)
    trajectories: dict[str, list] = {}
    for s in sorted(placed, key=lambda s: (s.robot, s.seq)):
        trajectories.setdefault(s.robot, []).append(poses[(s.robot, s.seq)][:3, 3])
    return GlobalMap(
        reference, merged, {k: np.array(v) for k, v in trajectories.items()}, sum(counts)
    )
