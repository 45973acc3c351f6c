"""Plain-numpy reference implementations the numba kernels are tested against.

Test tolerances live here, in one place (stumpy ``config.STUMPY_TEST_PRECISION``).
"""

#: Kernel versus plain-numpy reference, in m (1 pm): the two interpolate and take
#: square roots in a different order, which differs by rounding only.
ATOL_REFERENCE = 1e-12

#: Pruned versus exhaustive kernel, in m (1 fm); in practice bit-identical.
ATOL_IDENTICAL = 1e-15

#: Relative tolerance of the kinematic roughness oracles Rt, Ra (1 %).
RTOL_KINEMATIC = 0.01
