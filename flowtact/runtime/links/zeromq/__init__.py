"""The ZeroMQ link: every ZeroMQ specific of a stream that crosses processes, in one subpackage.

- :mod:`.streams`: a stream's two ends in the workers (PUSH and PULL sockets, their high-water
  mark from the stream's :class:`~flowtact.graphfile.deployment.Flow`, bind and connect, the ``block`` and
  ``latest`` policies), and where a supervisor binds each one (ipc:// on one host, tcp:// across);
- :mod:`.wire`: the framing of a chunk (a binary header plus raw numpy buffers; never pickle);
- :mod:`.security`: CurveZMQ keys, authentication and handshake checks for anything off-host.

The tick schedule that drives these ends is the worker's (:mod:`flowtact.runtime.worker`); the
in-process engine's local link is :mod:`flowtact.runtime.links.local`.
"""
