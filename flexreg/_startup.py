"""Start-up work that numba defers to the first call of a compiled function.

numba imports its NumPy support (and SciPy's BLAS bindings) and fills its typing and target
registries the first time any compiled function runs, which costs about 0.25 s in every new
process. Importing this module does that work at import time instead. The comparison's fork
server imports it with the other libraries (:data:`flexreg.comparison._PRELOAD`), so that a
method's measured call excludes its libraries' start-up alike: Open3D and OpenCV load
everything when they are imported.
"""

from __future__ import annotations

from numba.core.registry import cpu_target

cpu_target.target_context.refresh()
cpu_target.typing_context.refresh()
