"""A run: the prepared case and its blocks of frames, results and their files, the streaming runner, the stepping API, executors (local processes, Dask)."""
