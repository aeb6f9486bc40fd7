"""CurveZMQ for off-host streams: one pre-shared certificate per rig, and clear errors when keys differ.

flowtact never sends plain text between hosts. ``flowtact keys DIR`` (:func:`generate_keys`) writes one
CURVE certificate (``DIR/flowtact.key`` and ``DIR/flowtact.key_secret``, the secret with mode 0600);
the directory is copied to every host of the rig and named by the graph's ``network.keys`` or by
``$FLOWTACT_KEYS`` (:func:`load_keys`). On an off-host socket the binding side is the CURVE server
(:func:`secure_server`), the connecting sides are CURVE clients with the same keypair
(:func:`secure_client`), and an :class:`Authenticator` (a ZAP handler in a thread, one per context)
admits only that public key. Without a ZAP handler libzmq admits *any* client that knows the server's
public key, so :func:`secure_server` refuses to configure a socket whose context has no running
:class:`Authenticator`.

A failed handshake is silent in ZeroMQ (messages simply queue), so :class:`HandshakeWatch` reads the
socket monitor and turns failures into :class:`SecurityError`. What each side's monitor reports,
measured with libzmq 4.3.5 / pyzmq 27.3 on loopback tcp (every case is reported within milliseconds):

- right keys: both sides HANDSHAKE_SUCCEEDED;
- client with another keypair (the server's ZAP refuses it): both sides HANDSHAKE_FAILED_AUTH (ZAP
  status 400); the client does not retry;
- client with a wrong server public key: the server sees FAILED_PROTOCOL (ZMTP_CRYPTOGRAPHIC), the
  client only FAILED_NO_DETAIL (EPIPE: the server hung up), again at every reconnect interval;
- plain-text client against a CURVE server, or CURVE client against a plain-text server: both sides
  FAILED_PROTOCOL (ZMTP_MECHANISM_MISMATCH).

In none of the failing cases is a message delivered. The monitor must be attached (create the
:class:`HandshakeWatch`) before ``connect``/``bind`` so that no event is missed.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import os
import shutil
import stat
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import zmq
import zmq.auth
from zmq.auth.thread import ThreadAuthenticator
from zmq.utils import z85
from zmq.utils.monitor import recv_monitor_message

from flowtact.errors import SecurityError

__all__ = [
    "ENV_VAR",
    "PUBLIC_FILE",
    "SECRET_FILE",
    "Authenticator",
    "CurveKeys",
    "HandshakeWatch",
    "generate_keys",
    "is_loopback",
    "load_keys",
    "secure_client",
    "secure_server",
]

log = logging.getLogger("flowtact.security")

ENV_VAR = "FLOWTACT_KEYS"
"""Environment variable naming the keys directory (the graph's ``network.keys`` wins)."""

_NAME = "flowtact"
PUBLIC_FILE = f"{_NAME}.key"
"""The public certificate's file name inside the keys directory."""
SECRET_FILE = f"{_NAME}.key_secret"
"""The secret certificate's file name inside the keys directory (mode 0600)."""

HINT = (
    "create keys with `flowtact keys DIR`, copy DIR to every host of the rig, and name it in the "
    f"graph (`network.keys: DIR`) or in the environment ({ENV_VAR}=DIR)"
)
_SAME_KEYS = "both hosts must use the same `flowtact keys` directory"
_MAX_REFUSED = 100


@dataclass(frozen=True)
class CurveKeys:
    """The rig's CURVE keypair (z85-encoded, 40 bytes each) and where it was loaded from."""

    public: bytes
    secret: bytes = field(repr=False)
    source: str


# ----------------------------------------------------------------------------------------- key files


def generate_keys(directory: str | Path, force: bool = False) -> Path:
    """Write a new CURVE certificate pair into ``directory`` (created if needed) and return it.

    An existing secret certificate is kept (``SecurityError``) unless ``force`` is true: replacing it
    would lock out every host that still has the old copy. The pair is first written into a private
    (0700) temporary directory, the secret is set to 0600, and both files are then moved into place, so
    the secret is never readable by others, not even briefly.
    """
    directory = Path(directory).expanduser()
    secret = directory / SECRET_FILE
    if secret.exists() and not force:
        raise SecurityError(
            f"{secret} already exists; refusing to overwrite the rig's key (every host holding the old "
            "copy would be refused). Pass force=True (`flowtact keys --force`) to replace it."
        )
    try:
        directory.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".flowtact-keys-", dir=directory))
        try:
            public_tmp, secret_tmp = zmq.auth.create_certificates(tmp, _NAME)
            os.chmod(secret_tmp, stat.S_IRUSR | stat.S_IWUSR)
            os.chmod(public_tmp, 0o644)
            os.replace(secret_tmp, secret)
            os.replace(public_tmp, directory / PUBLIC_FILE)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    except OSError as exc:
        raise SecurityError(f"cannot write CURVE keys into {directory}: {exc}") from exc
    return directory


def load_keys(directory: str | Path | None) -> CurveKeys:
    """Load the rig's keypair from ``directory``, or from ``$FLOWTACT_KEYS`` when it is None.

    Raises :class:`SecurityError`, with a hint on how to create and name keys, when no directory is
    configured or the certificates are missing, unreadable, malformed or do not belong together.
    """
    if directory is None or str(directory) == "":
        env = os.environ.get(ENV_VAR, "")
        if not env:
            raise SecurityError(
                f"off-host streams need CURVE keys, and none are configured (no network.keys in the graph, "
                f"{ENV_VAR} unset): {HINT}"
            )
        path, source = Path(env).expanduser(), f"{ENV_VAR}={env}"
    else:
        path, source = Path(directory).expanduser(), str(directory)
    secret_file = path / SECRET_FILE
    if not path.is_dir():
        raise SecurityError(f"CURVE keys directory {path} (from {source}) does not exist: {HINT}")
    if not secret_file.is_file():
        raise SecurityError(f"CURVE keys directory {path} (from {source}) has no {SECRET_FILE}: {HINT}")
    try:
        public, secret = zmq.auth.load_certificate(secret_file)
    except (OSError, ValueError) as exc:
        raise SecurityError(f"cannot read CURVE certificate {secret_file}: {exc}; {HINT}") from exc
    if not (_valid_key(public) and secret is not None and _valid_key(secret)):
        raise SecurityError(f"{secret_file} is not a valid CURVE secret certificate: {HINT}")
    if zmq.curve_public(secret) != public:
        raise SecurityError(f"{secret_file}: the public key does not belong to the secret key: {HINT}")
    public_file = path / PUBLIC_FILE
    if public_file.is_file():
        try:
            listed = zmq.auth.load_certificate(public_file)[0]
        except (OSError, ValueError) as exc:
            raise SecurityError(f"cannot read CURVE certificate {public_file}: {exc}; {HINT}") from exc
        if listed != public:
            raise SecurityError(
                f"{public_file} and {secret_file} hold different keys (copied from two `flowtact keys` "
                f"runs?): {HINT}"
            )
    if os.name == "posix" and secret_file.stat().st_mode & 0o077:
        log.warning("%s is readable by other users; run `chmod 600 %s`", secret_file, secret_file)
    return CurveKeys(public=public, secret=secret, source=source)


def _valid_key(key: bytes) -> bool:
    if len(key) != 40:
        return False
    try:
        return len(z85.decode(key)) == 32
    except (ValueError, KeyError, TypeError):
        return False


def is_loopback(host: str) -> bool:
    """True for ``localhost``, 127.0.0.0/8 and ``::1`` (also ``[::1]`` and IPv4-mapped loopback)."""
    host = host.strip().strip("[]").rstrip(".").lower()
    if host == "localhost":
        return True
    try:
        addr = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return False
    if isinstance(addr, ipaddress.IPv6Address) and addr.ipv4_mapped is not None:
        addr = addr.ipv4_mapped
    return addr.is_loopback


# ------------------------------------------------------------------------------------ authenticator

_active_lock = threading.Lock()
_active: dict[int, int] = {}  # id(context) -> running Authenticators


class _RigAuthenticator(ThreadAuthenticator):
    """A ThreadAuthenticator that applies one policy to every ZAP domain and remembers the peer address."""

    address = ""

    async def handle_zap_message(self, msg: list[bytes]) -> None:
        if len(msg) >= 6:
            self.address = msg[3].decode("utf-8", "replace")
            if msg[5] == b"CURVE":
                msg = [*msg[:2], b"*", *msg[3:]]  # every domain gets the rig's policy
        await super().handle_zap_message(msg)


class _OnlyRigKey:
    """Credentials provider: admits the rig's public key, reports every other one to ``refuse``."""

    def __init__(self, rig_key: bytes, refuse: Callable[[bytes], None]) -> None:
        self.rig_key, self.refuse = rig_key, refuse

    def callback(self, domain: str, key: bytes) -> bool:  # noqa: ARG002 — pyzmq's signature; one policy for all domains
        if key == self.rig_key:
            return True
        self.refuse(key)
        return False


class Authenticator:
    """ZAP handler for one context: admits only ``keys.public`` on every domain (a context manager).

    Refusals are logged and kept in :attr:`refused` (the last 100, as messages such as "refused a
    connection from 10.0.0.7: unknown CURVE key Abc12…") and counted in :attr:`refused_count`.
    A context holds at most one running Authenticator.
    """

    def __init__(self, ctx: zmq.Context, keys: CurveKeys) -> None:
        self.ctx, self.keys = ctx, keys
        self.refused: list[str] = []
        self.refused_count = 0
        self._auth: _RigAuthenticator | None = None

    def start(self) -> Authenticator:
        """Start the ZAP thread (idempotent)."""
        if self._auth is not None:
            return self
        auth = _RigAuthenticator(self.ctx, log=log)
        try:
            auth.start()
        except zmq.ZMQError as exc:
            auth.stop()  # close the half-made ZAP socket, or ctx.term() would hang
            if exc.errno == zmq.EADDRINUSE:
                raise SecurityError("an Authenticator is already running in this ZeroMQ context") from exc
            raise
        auth.configure_curve_callback("*", _OnlyRigKey(self.keys.public, self._refuse))
        self._auth = auth
        with _active_lock:
            _active[id(self.ctx)] = _active.get(id(self.ctx), 0) + 1
        return self

    def stop(self) -> None:
        """Stop the ZAP thread and close its sockets (idempotent)."""
        if self._auth is None:
            return
        self._auth.stop()
        self._auth = None
        with _active_lock:
            left = _active.get(id(self.ctx), 0) - 1
            if left > 0:
                _active[id(self.ctx)] = left
            else:
                _active.pop(id(self.ctx), None)

    @property
    def running(self) -> bool:
        return self._auth is not None and self._auth.is_alive()

    def _refuse(self, key: bytes) -> None:
        address = self._auth.address if self._auth else "?"
        message = (
            f"refused a connection from {address}: unknown CURVE key {key[:8].decode('ascii', 'replace')}…"
        )
        log.warning("%s (%s)", message, _SAME_KEYS)
        self.refused_count += 1
        self.refused.append(message)
        del self.refused[:-_MAX_REFUSED]

    def __enter__(self) -> Authenticator:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()


# ---------------------------------------------------------------------------------- socket options


def secure_server(sock: zmq.Socket, keys: CurveKeys) -> None:
    """Make ``sock`` the CURVE server with the rig's keypair; call before ``bind``.

    Raises :class:`SecurityError` when no :class:`Authenticator` runs in the socket's context, since
    libzmq would then admit any client that knows the (public) server key.
    """
    with _active_lock:
        guarded = _active.get(id(sock.context), 0) > 0
    if not guarded:
        raise SecurityError(
            "a CURVE server socket needs a running Authenticator(ctx, keys) in its context; without one "
            "any client that knows the public key would be admitted"
        )
    sock.curve_secretkey = keys.secret
    sock.curve_publickey = keys.public
    sock.curve_server = True


def secure_client(sock: zmq.Socket, keys: CurveKeys) -> None:
    """Make ``sock`` a CURVE client with the rig's keypair, expecting the rig's server key; before ``connect``."""
    sock.curve_secretkey = keys.secret
    sock.curve_publickey = keys.public
    sock.curve_serverkey = keys.public


# --------------------------------------------------------------------------------- handshake watch

_FAILED = (
    zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL
    | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
    | zmq.EVENT_HANDSHAKE_FAILED_AUTH
)
_PROTOCOL_ERRORS = {
    getattr(zmq, n): n.removeprefix("PROTOCOL_ERROR_") for n in dir(zmq) if n.startswith("PROTOCOL_ERROR_")
}
_EVENTS = _FAILED | zmq.EVENT_HANDSHAKE_SUCCEEDED | zmq.EVENT_CONNECTED | zmq.EVENT_ACCEPTED


class HandshakeWatch:
    """Reports a socket's ZMTP/CURVE handshakes from its monitor; create it before ``connect``/``bind``.

    :meth:`check` raises :class:`SecurityError` for a failed handshake (each failure once) and
    :meth:`wait` blocks until one succeeds. :attr:`succeeded` holds the endpoints whose handshake
    succeeded.
    """

    def __init__(self, sock: zmq.Socket) -> None:
        self._sock = sock
        self._server = bool(sock.getsockopt(zmq.CURVE_SERVER))
        self._curve = sock.getsockopt(zmq.MECHANISM) == zmq.CURVE
        self._mon: zmq.Socket | None = sock.get_monitor_socket(_EVENTS)
        self.succeeded: set[str] = set()
        self._connected: set[str] = set()
        self._failures: list[str] = []

    def check(self) -> None:
        """Read pending monitor events without blocking; raise for a failed handshake."""
        while self._mon is not None and self._mon.poll(0):
            self._handle(recv_monitor_message(self._mon))
        self._raise_failure()

    def wait(self, timeout_s: float, endpoint: str | None = None) -> None:
        """Block until a handshake succeeds (with ``endpoint`` when given, any otherwise).

        Raises :class:`SecurityError` when a handshake fails or none succeeds within ``timeout_s``.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            self.check()
            if (endpoint in self.succeeded) if endpoint else self.succeeded:
                return
            left = deadline - time.monotonic()
            if left <= 0 or self._mon is None:
                break
            self._mon.poll(max(1, int(left * 1000)))
        where = endpoint or self._endpoint()
        tcp = " (the TCP connection was made, but the handshake never finished)" if self._connected else ""
        raise SecurityError(
            f"no CURVE handshake with {where} within {timeout_s:g} s{tcp}: is the peer running, "
            "and does it use the same keys?"
        )

    def close(self) -> None:
        """Stop the monitor and close its socket (idempotent; safe after the socket was closed)."""
        if self._mon is None:
            return
        if not self._sock.closed:
            with contextlib.suppress(zmq.ZMQError):
                self._sock.disable_monitor()
        self._mon.close(linger=0)
        self._mon = None

    def __enter__(self) -> HandshakeWatch:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- internals

    def _endpoint(self) -> str:
        try:
            return self._sock.last_endpoint.decode() or "the peer"
        except zmq.ZMQError:
            return "the peer"

    def _raise_failure(self) -> None:
        if self._failures:
            raise SecurityError(self._failures.pop(0))

    def _handle(self, event: dict[str, Any]) -> None:
        kind, value = int(event["event"]), int(event["value"])
        endpoint = event["endpoint"].decode("utf-8", "replace")
        if kind == zmq.EVENT_HANDSHAKE_SUCCEEDED:
            self.succeeded.add(endpoint)
        elif kind in (zmq.EVENT_CONNECTED, zmq.EVENT_ACCEPTED):
            self._connected.add(endpoint)
        elif kind & _FAILED:
            self._failures.append(self._explain(kind, value, endpoint))

    def _explain(self, kind: int, value: int, endpoint: str) -> str:
        mismatch = (
            kind == zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
            and value == zmq.PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH
        )
        crypto = (
            kind == zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL and value == zmq.PROTOCOL_ERROR_ZMTP_CRYPTOGRAPHIC
        )
        if self._server:
            if kind == zmq.EVENT_HANDSHAKE_FAILED_AUTH:
                why = "the client's CURVE key is not this rig's key (Authenticator.refused names its address)"
            elif mismatch:
                why = "the client is plain text, and off-host streams must use CURVE"
            elif crypto:
                why = "the client expects another server key"
            else:
                why = _detail(kind, value)
            return f"refused a connection on {endpoint}: {why} ({_SAME_KEYS})"
        if mismatch and not self._curve:
            return (
                f"handshake with {endpoint} refused: the peer requires CURVE encryption and this socket is "
                f"plain text: {HINT}"
            )
        if mismatch:
            return (
                f"CURVE handshake with {endpoint} refused: the peer is a plain-text socket, and off-host "
                f"streams must use CURVE on both ends ({_SAME_KEYS})"
            )
        if kind == zmq.EVENT_HANDSHAKE_FAILED_AUTH:
            return (
                f"CURVE handshake with {endpoint} refused: the peer does not accept this key ({_SAME_KEYS})"
            )
        if kind == zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL and self._curve:
            return (
                f"CURVE handshake with {endpoint} failed: the peer dropped the connection, most likely because "
                f"its key is not the server key this host expects ({_SAME_KEYS})"
            )
        return f"handshake with {endpoint} failed: {_detail(kind, value)} ({_SAME_KEYS})"


def _detail(kind: int, value: int) -> str:
    name = zmq.Event(kind).name
    if kind == zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL:
        return f"{name} ({_PROTOCOL_ERRORS.get(value, hex(value))})"
    if kind == zmq.EVENT_HANDSHAKE_FAILED_AUTH:
        return f"{name} (ZAP status {value})"
    return f"{name} ({os.strerror(value) if value > 0 else value})"
