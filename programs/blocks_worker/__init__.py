"""Blocks made into Python outside the server's and the agents' processes.

How much Python blocks make, and how long compiling it takes, is the author's to decide; made
in the server (or an agent) it held the interpreter lock and kept the memory: 300 if blocks of
1000 else-ifs each took 22 s and 1 GB there, /healthz and the e-stop waiting. programs.blocks
now refuses blocks too large before making any code; what it makes and compiles it does in a
worker process (`python -m programs.blocks_worker`) started by prlimit with an address-space
cap, at a lower priority, with a CPU cap per program, and killed past its wall time. A few
workers are kept running (a fresh interpreter with Django's translations for each refresh of
the workbench's Python pane took 0.3-1 s); one that dies or is killed is replaced on the next
call. A caller waits on a pipe, which holds no lock: call from a thread, never the event loop.

    to_python(source)           its Python, or BlocksError (a ValueError) saying why not
    to_python_mapped(source)    that Python and its source map (a block id for each line)
    to_runnable_python(source)  what a run writes: that Python, or a program failing saying why
"""

from programs.blocks_worker.pool import BlocksBusy, to_python, to_python_mapped, to_runnable_python

__all__ = ["BlocksBusy", "to_python", "to_python_mapped", "to_runnable_python"]
