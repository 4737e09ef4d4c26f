"""Request handlers, one module per concern, each exporting ``HANDLERS = {RequestClass: function}``.

A handler is a function ``(ctx, request) -> Reply`` (or ``-> jobs.Job`` for long work); it raises
``ArboretumError`` for a user's mistake and never touches a socket, so each is testable on its own.
"""
