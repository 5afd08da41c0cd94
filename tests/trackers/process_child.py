"""A scripted tracker process for the tests: speaks the protocol with msgpack alone (it starts in
a tenth of a second) and misbehaves as its first argument says.

    python process_child.py MODE

MODE ``ok`` replies well-formed identity estimates; ``crash`` prints to stderr and exits 3 at the
first observation; ``hang`` sleeps at the first observation; ``error`` replies an error message;
``print`` prints to stdout (which would corrupt the protocol without a redirect, so it is a
protocol error here); any other mode names a broken estimate (see ``BROKEN``).
"""

from __future__ import annotations

import os
import struct
import sys
import time

import msgpack

HEADER = struct.Struct("<I")


def array(values, dtype="float64", shape=None):
    data = struct.pack(f"<{len(values)}d", *values) if dtype == "float64" else bytes(values)
    return {"dtype": dtype, "shape": [len(values)] if shape is None else shape, "data": data}


def estimate(k):
    return {
        "type": "estimate",
        "k": k,
        "valid": True,
        "t_m": array([0.0, 0.0, 0.5]),
        "q_wxyz": array([1.0, 0.0, 0.0, 0.0]),
        "v_obj_mps": array([0.0, 0.0, 0.0]),
        "w_radps": array([0.0, 0.0, 0.0]),
    }


BROKEN = {
    "wrong_k": lambda m: m | {"k": m["k"] + 1},
    "wrong_shape": lambda m: m | {"t_m": array([0.0, 0.0, 0.5, 1.0])},
    "nan": lambda m: m | {"v_obj_mps": array([0.0, float("nan"), 0.0])},
    "non_unit": lambda m: m | {"q_wxyz": array([1.0, 0.1, 0.0, 0.0])},
    "missing": lambda m: {k: v for k, v in m.items() if k != "w_radps"},
    "wrong_dtype": lambda m: m | {"t_m": array([0, 0, 0], dtype="uint8")},
    "unknown_field": lambda m: m | {"q_xyzw": m["q_wxyz"]},
}


def read():
    header = sys.stdin.buffer.read(HEADER.size)
    if len(header) < HEADER.size:
        return None
    (n,) = HEADER.unpack(header)
    return msgpack.unpackb(sys.stdin.buffer.read(n))


def send(message):
    payload = msgpack.packb(message, use_bin_type=True)
    sys.stdout.buffer.write(HEADER.pack(len(payload)) + payload)
    sys.stdout.buffer.flush()


def main(mode):
    while (message := read()) is not None:
        kind = message["type"]
        if kind in ("hello", "reset"):
            send({"type": "ready", "protocol": 1, "name": f"child-{mode}"})
        elif kind == "bye":
            return 0
        elif mode == "crash":
            print("child: something went wrong in native code", file=sys.stderr, flush=True)
            os._exit(3)
        elif mode == "hang":
            print("child: thinking very hard", file=sys.stderr, flush=True)
            time.sleep(60)
        elif mode == "error":
            send({"type": "error", "message": "out of ideas"})
            return 1
        elif mode == "print":
            sys.stdout.write("hello from a print\n")
            sys.stdout.flush()
        else:
            send(BROKEN.get(mode, lambda m: m)(estimate(message["k"])))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
