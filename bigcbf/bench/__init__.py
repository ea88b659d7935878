"""Many episodes: the paper's Sec. IV benchmark (``bigcbf bench``), resumable, locally or on Ray.

- :mod:`.tasks`: the picklable episode task and the function a worker runs (``guarded(run_episode, task)``).
- :mod:`.store`: the SQLite results database (WAL; one row per episode; written by the parent only).
- :mod:`.engines`: the local process pool and the Ray engine.
- :mod:`.report`: aggregation, episodes.csv, summary.json/.md, figures.
- :mod:`.runner`: :func:`run_bench` ties them together.
- :mod:`.paper`: the paper's Table II and quoted per-scenario numbers.
- :mod:`.variants`: the switches ``--variant NAME=V1,V2`` compares (every method under every combination).

Kept import-light: a spawned worker imports this package before it runs anything.
"""
