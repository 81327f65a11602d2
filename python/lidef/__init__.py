"""lidef: certified locally injective volumetric deformation (Liao et al., TOG 2021) from Python.

Arrays in and out are numpy: points float64 ``n x 3``, faces int ``n x 3``. Every call releases the GIL while it
computes; Ctrl-C stops a long call at its next unit of work (the last certified map is kept) and raises
KeyboardInterrupt. Bad input raises :class:`InputError` (a ``ValueError``) naming the file or argument.

    import lidef
    model = lidef.load_model("data/models/beam")
    sc = lidef.read_scenario("data/scenarios/beam_bend.json")
    result = lidef.deform(model, sc.sources, sc.targets, reduced_dof=60)
    print(result.certified, result.max_handle_error)

docs/tutorial.md walks through it; ``lidef.parameters()`` lists every keyword ``**params`` takes.
"""

# OpenBLAS's kernels: the compiled part selects the CPU's kernels in-process when it is imported (where
# OpenBLAS fell back to its SSE3 ones), so nothing needs to be set before this import.
from ._lidef import (
    Certificate,
    DeformResult,
    Error,
    InputError,
    Model,
    Scenario,
    Session,
    certify,
    deform,
    load_model,
    parameters,
    read_scenario,
    search_sigma3_minima,
)

__version__ = "@PROJECT_VERSION@"

__all__ = [
    "Certificate",
    "DeformResult",
    "Error",
    "InputError",
    "Model",
    "Scenario",
    "Session",
    "certify",
    "deform",
    "load_model",
    "parameters",
    "read_scenario",
    "search_sigma3_minima",
]
