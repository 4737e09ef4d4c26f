"""Library building at scale: many scans decomposed in parallel with Dask, examples stored by the client.

``build.build_library`` submits one task per scan (``tasks.decompose_scan``) to a Dask cluster (a
``LocalCluster`` by default, or an existing scheduler) and adds each scan's examples to the library as
its future completes; only the calling process writes to the library. ``scans`` expands the SCAN
arguments, ``plan`` decides what a rerun skips, notes or redoes, ``waiting`` reports a cluster without
workers, ``report.write_report`` turns a build into markdown and PNG plots. Dask is imported inside the
submodules, never here.
"""
