"""The first module a local cluster's fork server imports: no cyclic garbage collection until it forks.

The server (`cosim.sweep.warm`) imports Dask and the run stage and makes a short warm-up run,
~10^5 objects that live as long as the server and its workers; Python's collector would walk them
again and again while they are made, finding almost nothing (0.05-0.1 s of the server's ~0.55 s
of CPU before it can fork the first worker, measured on 2 cores). With a warm-up request in the
environment (`WARM_ENV`), importing this module switches the collector off; `cosim.sweep.warm`,
the last module the server imports, freezes what was made (`gc.freeze`) and switches it on again,
before any worker is forked. It also ignores SIGINT and SIGTERM in a server started so, warm-up
or not (`WARM_ENV` set, maybe empty). Without it, importing this module changes nothing.
"""

from __future__ import annotations

import gc
import os
import signal

WARM_ENV = "NAVCOSIM_SWEEP_WARM"  # the warm-up request (JSON), set for the fork server only

if WARM_ENV in os.environ:  # a fork server that `cosim.sweep.warm` starts afresh
    # Ctrl-C (or SIGTERM to the process group) ends the sweep, which closes the server and its
    # workers: ignored here, before multiprocessing's server keeps the dispositions it finds for the
    # workers it forks (both are blocked until then: `cosim.sweep.warm.ensure_fork_server`).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    if os.environ[WARM_ENV]:
        gc.disable()
