"""The Wigner-3j / Gaunt engine, in the order of its pipeline.

:mod:`~shspec.gaunt.wigner` (3j families by the Schulten–Gordon recursion, double precision, for the table builder)
and :mod:`~shspec.gaunt.wigner_dd` (its double-double twin behind the public :func:`wigner3j`, on the arithmetic of
:mod:`~shspec.gaunt.doubledouble`) → :mod:`~shspec.gaunt.real_gaunt` (real Gaunt coefficients ∫Y_iY_jY_k) →
:mod:`~shspec.gaunt.table` (the stored layout and the assembly kernels of :class:`GauntTable`) →
:mod:`~shspec.gaunt.build` (computing a table) → :mod:`~shspec.gaunt.cache` (validated HDF5 files, :func:`get_table`).
The ``precompute`` command line is a thin shell over this package.
"""

from .build import build_table
from .cache import cache_dir, get_table, list_tables, load_table, save_table, table_path, verify_table
from .real_gaunt import real_gaunt
from .table import GauntTable, table_size
from .wigner_dd import wigner3j, wigner3j_family

__all__ = ["wigner3j", "wigner3j_family", "real_gaunt", "GauntTable", "table_size", "build_table", "get_table",
           "load_table", "save_table", "list_tables", "verify_table", "cache_dir", "table_path"]
