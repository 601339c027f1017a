"""Numba kernels: module-level @njit functions over arrays and scalars only (design guide §3)."""
