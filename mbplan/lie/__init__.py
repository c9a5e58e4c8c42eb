"""Matrix Lie groups with one API for numeric (NumPy) and symbolic (CasADi) arguments.

>>> from mbplan.lie import SO3
>>> R = SO3.exp([0.0, 0.0, 0.5])
>>> SO3.log(R)
array([0. , 0. , 0.5])
"""

from mbplan.lie.group import MatrixLieGroup
from mbplan.lie.product import ProductGroup
from mbplan.lie.rn import R, RnGroup
from mbplan.lie.se3 import SE3, SE3Group
from mbplan.lie.so3 import SO3, SO3Group
from mbplan.lie.son import SL, SO, SLnGroup, SOnGroup

__all__ = [
    "SE3",
    "SL",
    "SO",
    "SO3",
    "MatrixLieGroup",
    "ProductGroup",
    "R",
    "RnGroup",
    "SE3Group",
    "SLnGroup",
    "SO3Group",
    "SOnGroup",
]
