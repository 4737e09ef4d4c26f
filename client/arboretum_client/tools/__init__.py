"""Interaction tools: client state, actions over the session port, hand-event routing, drag maths, scene views."""
