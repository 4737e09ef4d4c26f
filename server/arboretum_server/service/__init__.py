"""The ZeroMQ service behind ``arboretum serve`` (VRTree section 4.1, without the shared disk).

``socket`` owns the ROUTER socket and the poll loop, ``frames`` reads request envelopes and ``flow`` bounds
the replies remembered and the bytes queued per client; ``dispatch`` finds the handler of each typed request
(``arboretum_library.protocol``) among the modules of ``handlers``; handlers are functions request ->
reply, or -> ``jobs.Job`` for long work that runs in worker processes (``jobs``); ``sessions`` keeps each
client's assembly with undo/redo and autosave; ``keys`` makes CurveZMQ key files.
"""
