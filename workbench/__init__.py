"""EDL reconstruction workbench.

Importing the package sets numba's optimisation level for the compiled kernels to 2
(``NUMBA_OPT``, unless the environment already sets it): numba reads ``NUMBA_OPT`` at its import
and again before each compilation (``numba.core.config.reload_config``), and every kernel module
imports this package first, so the level applies to the first compile in this process and in the
processes it starts (the precompiling child, Monte Carlo workers). Level 2 compiles the kernels of
a fresh checkout in less CPU than numba's default 3 with the same results to the bit; the
measurements are in docs/RESULTS.md ("The first run's compile").
"""

import os

os.environ.setdefault("NUMBA_OPT", "2")
