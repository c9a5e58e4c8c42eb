"""mbplan: trajectory optimization of multi-body robots on matrix Lie groups."""

from mbplan.errors import MbplanError

__all__ = ["MbplanError"]
__version__ = "0.1.0"
