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


class Control:
    """Control(path=None, timeout=30): path defaults to $DS1928_SOCKET or the package's path."""

    def __init__(self, path=None, timeout=30.0):
        self.path = path or os.environ.get("DS1928_SOCKET", DEFAULT_SOCKET)
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._sock.settimeout(timeout)
        self._sock.connect(self.path)
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
