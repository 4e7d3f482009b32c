"""EM benchmark: gmmap vs scikit-learn's GaussianMixture, plus scaling in N and K.

50,000 points of a real indoor scene (voxelised TUM fr1_xyz frames), K=100, diagonal
covariances, k-means++ initialisation, 30 fixed iterations (tol=0) for both, in one run.
Prints one JSON object: both times, the speed-up, both final mean log-likelihoods (scored
exactly on the same points), and time / peak extra memory for N = 10k…500k and K = 25…400.

    .venv/bin/python benchmarks/em.py [--no-scaling] [extra `gmmap bench em` options]
"""

import sys

from gmmap.cli import main

if __name__ == "__main__":
    args = sys.argv[1:]
    scaling = [] if "--no-scaling" in args else ["--scaling"]
    args = [a for a in args if a != "--no-scaling"]
    sys.exit(main(["bench", "em", "--json", *scaling, *args]))
