#!/usr/bin/env python3
"""Reference adapter for robocal's open link protocol (robotio/OPEN_LINK.md).

Copy this file beside your controller and replace SimulatedRobot with a class that talks to it
(same methods). Everything else -- framing, request ids, repeated replies, version negotiation,
error codes, keep-alives, settled notifications, stops acted on receipt -- is the protocol and
stays as it is. Python 3 standard library only.

Run it on its own to get a trivial simulated robot that `robocal link-check` can be tried on:

    python3 open_link_adapter.py --port 7001
    robocal link-check open:127.0.0.1:7001 --lower 0.05,0.05,0.05 --upper 0.3,0.3,0.3
"""

import argparse
import json
import math
import selectors
import socket
import sys
import time

PROTOCOL = "robocal-open-link"
VERSION = (1, 0)

# Error codes (OPEN_LINK.md, "Error codes").
MALFORMED, UNKNOWN_COMMAND, BAD_ARGUMENTS, VERSION_UNSUPPORTED = 100, 101, 102, 103
REFUSED_FOR_NOW, OUTSIDE_LIMITS, HALTED, HARDWARE_FAULT, STOPPED = 200, 201, 202, 203, 204


class ProtocolError(Exception):
    """A request the controller does not execute; becomes an error reply."""

    def __init__(self, code, message):
        super().__init__(message)
        self.code = code
        self.message = message


class SimulatedRobot:
    """A trivial robot: straight-line moves at constant speed, positions quantised to counts.

    Replace it with your controller. The methods are all the adapter needs:
      actuators()          -> [(name, unit "m"|"rad", resolution)]
      start_move(target, speed, acceleration)   (positions in SI units; raise ProtocolError)
      update()             called every few ms: advance the motion, read the hardware
      moving()             -> bool
      position()           -> (positions in SI units, counts or None)
      stop(emergency)      halt now; drop queued moves
      home()               start moving to the reference position
    """

    name = "open link reference adapter (simulated robot)"
    capabilities = ["counts", "home", "emergency_stop", "settled_event"]

    def __init__(self, count, unit, resolution, home, lower, upper):
        self.count = count
        self.unit = unit
        self.resolution = resolution
        self.home_position = home
        self.lower, self.upper = lower, upper
        self.counts = [round(v / resolution) for v in home]
        self.motion = None  # (start counts, target counts, start time, duration)

    def actuators(self):
        return [("q%d" % (i + 1), self.unit, self.resolution) for i in range(self.count)]

    def start_move(self, target, speed, acceleration):
        for i, v in enumerate(target):
            if not self.lower[i] <= v <= self.upper[i]:
                raise ProtocolError(OUTSIDE_LIMITS, "actuator %d target %g outside %g..%g %s" % (
                    i + 1, v, self.lower[i], self.upper[i], self.unit))
        self.update()
        goal = [round(v / self.resolution) for v in target]
        length = math.dist([c * self.resolution for c in self.counts],
                           [c * self.resolution for c in goal])
        self.motion = (list(self.counts), goal, time.monotonic(), length / speed)

    def home(self):
        self.start_move(self.home_position, 0.05, 1.0)

    def update(self):
        if self.motion is None:
            return
        start, goal, t0, duration = self.motion
        s = 1.0 if duration <= 0 else min(1.0, (time.monotonic() - t0) / duration)
        self.counts = [round(a + s * (b - a)) for a, b in zip(start, goal)]
        if s >= 1.0:
            self.motion = None

    def moving(self):
        self.update()
        return self.motion is not None

    def position(self):
        self.update()
        return [c * self.resolution for c in self.counts], list(self.counts)

    def stop(self, emergency):
        self.update()
        self.motion = None


class Connection:
    """One client (robocal). Request ids, the repeated reply, waits and keep-alives."""

    def __init__(self, sock, robot, keepalive):
        self.sock = sock
        self.robot = robot
        self.keepalive = keepalive
        self.inbuf = b""
        self.last_id = None
        self.last_reply = None
        self.wait_id = None  # a wait_settled or home waiting for the motion to end
        self.next_busy = 0.0
        self.motions = 0
        self.notified = 0

    def send(self, obj):
        self.sock.sendall((json.dumps(obj) + "\n").encode("utf-8"))

    def reply(self, request_id, body):
        body["id"] = request_id
        self.last_id, self.last_reply = request_id, body
        self.send(body)

    def error(self, request_id, code, message):
        self.reply(request_id, {"ok": False, "error": {"code": code, "message": message}})


class Adapter:
    def __init__(self, robot, keepalive=1.0):
        self.robot = robot
        self.keepalive = keepalive
        self.halted = False
        self.stopped = False

    # ---- one request ---------------------------------------------------------------------------

    def handle_line(self, conn, line):
        try:
            request = json.loads(line)
        except ValueError:
            request = None
        if (not isinstance(request, dict) or not isinstance(request.get("id"), int)
                or isinstance(request.get("id"), bool) or not isinstance(request.get("cmd"), str)):
            rid = request.get("id") if isinstance(request, dict) else None
            conn.send({"id": rid, "ok": False, "error": {
                "code": MALFORMED,
                "message": "malformed request: expected one JSON object with an integer "
                           "\"id\" and a \"cmd\""}})
            return
        rid, cmd = request["id"], request["cmd"]
        if rid == conn.last_id:
            conn.send(conn.last_reply)  # the client lost our reply: the same again, not re-executed
            return
        if cmd == "stop":
            self.stop(conn, request.get("kind", "controlled"))
            conn.reply(rid, {"ok": True, "state": "halted" if self.halted else "stopped"})
            return
        if self.halted and cmd not in ("reset", "state", "hello"):
            conn.error(rid, HALTED, "halted by an emergency stop: send reset")
            return
        handler = getattr(self, "cmd_" + cmd, None)
        if handler is None:
            conn.error(rid, UNKNOWN_COMMAND, "unknown command '%s'" % cmd)
            return
        try:
            body = handler(conn, request)
        except ProtocolError as e:
            conn.error(rid, e.code, e.message)
            return
        if body is None:  # answered when the motion ends
            conn.wait_id = rid
            conn.next_busy = time.monotonic() + self.keepalive
        else:
            conn.reply(rid, body)

    def stop(self, conn, kind):
        self.robot.stop(kind == "emergency")
        self.halted = self.halted or kind == "emergency"
        self.stopped = kind != "emergency"
        if conn.wait_id is not None:
            conn.error(conn.wait_id, STOPPED, "motion stopped by a %s stop" % kind)
            conn.wait_id = None

    def position_fields(self):
        position, counts = self.robot.position()
        body = {"position": position}
        if counts is not None:
            body["counts"] = counts
        return body

    def cmd_hello(self, conn, request):
        if request.get("protocol") != PROTOCOL:
            raise ProtocolError(BAD_ARGUMENTS, "\"protocol\" must be \"%s\"" % PROTOCOL)
        version = request.get("version")
        if (not isinstance(version, list) or len(version) != 2
                or not all(isinstance(v, int) for v in version)):
            raise ProtocolError(BAD_ARGUMENTS, "\"version\" must be [major, minor]")
        if version[0] != VERSION[0]:
            raise ProtocolError(VERSION_UNSUPPORTED,
                                "this controller speaks %s %d.%d; the client asked for %d.%d"
                                % (PROTOCOL, VERSION[0], VERSION[1], version[0], version[1]))
        return {"ok": True, "protocol": PROTOCOL, "version": list(VERSION),
                "controller": self.robot.name, "capabilities": self.robot.capabilities,
                "actuators": [{"name": n, "unit": u, "resolution": r}
                              for n, u, r in self.robot.actuators()],
                "keepalive_s": self.keepalive}

    def cmd_move(self, conn, request):
        target, n = request.get("target"), len(self.robot.actuators())
        if (not isinstance(target, list) or len(target) != n
                or not all(isinstance(v, (int, float)) for v in target)):
            raise ProtocolError(BAD_ARGUMENTS, "\"target\" needs %d numbers (one per actuator), "
                                               "got %s" % (n, json.dumps(target)))
        speed, acceleration = request.get("speed"), request.get("acceleration")
        if not all(isinstance(v, (int, float)) and v > 0 for v in (speed, acceleration)):
            raise ProtocolError(BAD_ARGUMENTS, "\"speed\" and \"acceleration\" must be positive")
        self.robot.start_move([float(v) for v in target], float(speed), float(acceleration))
        self.stopped = False
        conn.motions += 1
        return {"ok": True, "motion": conn.motions}

    def cmd_wait_settled(self, conn, request):
        if self.robot.moving():
            return None
        body = {"ok": True, "motion": conn.motions}
        body.update(self.position_fields())
        return body

    def cmd_home(self, conn, request):
        self.robot.home()
        self.stopped = False
        conn.motions += 1
        return self.cmd_wait_settled(conn, request)

    def cmd_read(self, conn, request):
        body = {"ok": True, "moving": self.robot.moving()}
        body.update(self.position_fields())
        return body

    def cmd_state(self, conn, request):
        state = ("halted" if self.halted else "moving" if self.robot.moving()
                 else "stopped" if self.stopped else "idle")
        return {"ok": True, "state": state, "motion": conn.motions}

    def cmd_reset(self, conn, request):
        self.halted = False
        return {"ok": True, "state": "idle"}

    # ---- waiting -------------------------------------------------------------------------------

    def tick(self, conn):
        now = time.monotonic()
        moving = self.robot.moving()
        if conn.wait_id is not None:
            if not moving:
                body = {"ok": True, "motion": conn.motions}
                body.update(self.position_fields())
                rid, conn.wait_id = conn.wait_id, None
                conn.reply(rid, body)
            elif self.keepalive > 0 and now >= conn.next_busy:
                conn.send({"event": "busy"})
                conn.next_busy = now + self.keepalive
        if not moving and conn.notified < conn.motions:
            conn.notified = conn.motions
            event = {"event": "settled", "motion": conn.motions}
            event.update(self.position_fields())
            conn.send(event)


def serve(adapter, host, port, max_seconds, exit_with_parent):
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    listener.bind((host, port))
    listener.listen(1)
    print("listening %s:%d" % listener.getsockname(), flush=True)
    selector = selectors.DefaultSelector()
    selector.register(listener, selectors.EVENT_READ, "listen")
    if exit_with_parent:
        selector.register(sys.stdin, selectors.EVENT_READ, "parent")
    conn = None
    end = time.monotonic() + max_seconds if max_seconds > 0 else float("inf")
    while time.monotonic() < end:
        for key, _ in selector.select(timeout=0.02):
            if key.data == "parent":
                if not sys.stdin.readline():
                    return
            elif key.data == "listen":
                sock, _ = listener.accept()
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                if conn is not None:  # one client at a time: the newest wins
                    selector.unregister(conn.sock)
                    conn.sock.close()
                conn = Connection(sock, adapter.robot, adapter.keepalive)
                selector.register(sock, selectors.EVENT_READ, "client")
            elif conn is not None:
                try:
                    data = conn.sock.recv(65536)
                except OSError:
                    data = b""
                if not data:
                    selector.unregister(conn.sock)
                    conn.sock.close()
                    conn = None
                    continue
                conn.inbuf += data
                while conn is not None and b"\n" in conn.inbuf:
                    line, conn.inbuf = conn.inbuf.split(b"\n", 1)
                    line = line.rstrip(b"\r").decode("utf-8", "replace")
                    if line:
                        try:
                            adapter.handle_line(conn, line)
                        except OSError:
                            selector.unregister(conn.sock)
                            conn.sock.close()
                            conn = None
        if conn is not None:
            try:
                adapter.tick(conn)
            except OSError:
                selector.unregister(conn.sock)
                conn.sock.close()
                conn = None


def numbers(text):
    return [float(v) for v in text.split(",")]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=7001, help="0 = any free port (printed)")
    p.add_argument("--actuators", type=int, default=3)
    p.add_argument("--unit", choices=["m", "rad"], default="m")
    p.add_argument("--resolution", type=float, default=1e-5)
    p.add_argument("--home", type=numbers, default=None, help="start position, comma list")
    p.add_argument("--lower", type=numbers, default=None, help="the robot's own limits")
    p.add_argument("--upper", type=numbers, default=None)
    p.add_argument("--keepalive", type=float, default=1.0)
    p.add_argument("--max-seconds", type=float, default=0.0)
    p.add_argument("--exit-with-parent", action="store_true",
                   help="exit when standard input closes")
    a = p.parse_args()
    n = a.actuators
    home = a.home or [0.2] * n
    lower = a.lower or [-1e9] * n
    upper = a.upper or [1e9] * n
    if not len(home) == len(lower) == len(upper) == n:
        p.error("--home, --lower and --upper need %d values each" % n)
    robot = SimulatedRobot(n, a.unit, a.resolution, home, lower, upper)
    try:
        serve(Adapter(robot, a.keepalive), a.host, a.port, a.max_seconds, a.exit_with_parent)
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
