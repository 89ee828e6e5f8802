"""Remote simulation: a server that runs the physics of named scenes, and clients that
watch and edit them together over WebSocket (PROTOCOL.md).

    wmo serve                                  # a server on ws://127.0.0.1:8765
    scene = wmo.remote.connect("ws://127.0.0.1:8765", scene="lab")
    h = scene.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0, 5, 0), mass=1.0)
    scene.set_pose(h, position=(1, 5, 0))
    scene.positions                            # latest snapshot, (N, 3)

Needs the ``remote`` extra (``websockets``, ``msgpack``).
"""
from __future__ import annotations

from .scene import EditError, SceneModel

__all__ = ["EditError", "SceneModel", "connect", "connect_async", "Server", "RemoteError"]


def __getattr__(name):  # the network parts import websockets only when used
    if name in ("connect", "connect_async", "RemoteScene", "AsyncRemoteScene", "RemoteError"):
        from . import client
        return getattr(client, name)
    if name == "Server":
        from .server import Server
        return Server
    raise AttributeError(name)
