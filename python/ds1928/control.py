"""Client of ds1928d's control socket: one JSON object per line (docs/socket-protocol.md)."""
import json
import os
import socket

DEFAULT_SOCKET = "/run/ds1928d/control.sock"


class ControlError(Exception):
    """The daemon answered {"ok":false}: .code and .message are its error."""

    def __init__(self, code, message, reply=None):
        super().__init__(f"{code}: {message}")
        self.code, self.message, self.reply = code, message, reply


class DaemonUnreachable(ConnectionError):
    """No daemon listens on any of the socket paths tried: .paths lists them, .errors the
    OSError of each."""

    def __init__(self, paths, errors):
        tried = ", nor to ".join(f"{p} ({e.strerror or e})" for p, e in zip(paths, errors))
        absent = all(isinstance(e, (FileNotFoundError, ConnectionRefusedError)) for e in errors)
        super().__init__(f"cannot connect to {tried}"
                         + (": is ds1928d running?" if absent else ""))
        self.paths, self.errors = list(paths), list(errors)


def fallback_socket_path(path):
    """Where a daemon that cannot create `path`'s directory (started without root) puts its
    socket: the same file name in $XDG_RUNTIME_DIR/ds1928d/, or /tmp/ds1928d-<uid>/ (as the
    daemon's ds1928::fallback_socket_path())."""
    name = path.rsplit("/", 1)[-1] or "control.sock"
    xdg = os.environ.get("XDG_RUNTIME_DIR", "")
    if xdg.startswith("/"):
        return f"{xdg}/ds1928d/{name}"
    return f"/tmp/ds1928d-{os.getuid()}/{name}"


def socket_paths(path=None):
    """The paths Control tries, in order: `path`, else $DS1928_SOCKET, else the default; then
    that path's fallback (as ds1928ctl)."""
    chosen = path or os.environ.get("DS1928_SOCKET") or DEFAULT_SOCKET
    fallback = fallback_socket_path(chosen)
    return [chosen] if fallback == chosen else [chosen, fallback]


class Control:
    """Control(path=None, timeout=30): path defaults to $DS1928_SOCKET or the package's path,
    each followed by the daemon's per-user fallback. Raises DaemonUnreachable naming every path
    tried when none answers."""

    def __init__(self, path=None, timeout=30.0):
        errors = []
        paths = socket_paths(path)
        for candidate in paths:
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            sock.settimeout(timeout)
            try:
                sock.connect(candidate)
            except OSError as e:
                sock.close()
                errors.append(e)
                continue
            self.path, self._sock = candidate, sock
            break
        else:
            raise DaemonUnreachable(paths, errors)
        self._buffer = b""
        self._next_id = 1

    def close(self):
        self._sock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def request(self, cmd, **arguments):
        """Sends {"cmd": cmd, ...} and returns the reply object; raises ControlError on ok=false."""
        rid = self._next_id
        self._next_id += 1
        self._sock.sendall((json.dumps(dict(arguments, cmd=cmd, id=rid)) + "\n").encode())
        while True:
            reply = json.loads(self._line())
            if "ok" not in reply:
                continue  # capture data lines precede their reply
            if reply.get("id") != rid:
                continue
            if not reply["ok"]:
                error = reply.get("error", {})
                raise ControlError(error.get("code", "?"), error.get("message", ""), reply)
            return reply

    def _line(self):
        while b"\n" not in self._buffer:
            chunk = self._sock.recv(65536)
            if not chunk:
                raise ConnectionError(f"{self.path}: the daemon closed the connection")
            self._buffer += chunk
        line, self._buffer = self._buffer.split(b"\n", 1)
        return line

    # The usual commands.
    def status(self):
        return self.request("status")

    def axes(self):
        return self.request("axes")

    def stats(self):
        return self.request("stats")

    def endat_ident(self, axis=0, refresh=False):
        return self.request("endat-ident", axis=axis, refresh=refresh)

    def endat_read_param(self, mrs, param, axis=0):
        return self.request("endat-read-param", axis=axis, mrs=mrs, param=param)

    def endat_write_param(self, mrs, param, value, axis=0):
        return self.request("endat-write-param", axis=axis, mrs=mrs, param=param, value=value)

    def endat_reset(self, axis=0):
        return self.request("endat-reset", axis=axis)

    def endat_ack(self, axis=0):
        return self.request("endat-ack", axis=axis)

    def ack_errors(self, axis, bits):
        return self.request("ack-errors", axis=axis, bits=bits)
