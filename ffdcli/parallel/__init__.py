"""MPI runs: the communicator (comm), a rank's share of a mesh (partition), reductions over ranks (distributed)."""

from ffdcli.parallel.comm import (  # the face: the names `ffdcli.parallel` offered before the packages
    SIZE_VARIABLES,
    MPIComm,
    RankError,
    SerialComm,
    launched_size,
    mpi_available,
    share,
    world,
)

__all__ = [
    "SIZE_VARIABLES",
    "MPIComm",
    "RankError",
    "SerialComm",
    "launched_size",
    "mpi_available",
    "share",
    "world",
]
