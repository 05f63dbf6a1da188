"""An agent behind HTTP, Python standard library only: the reference of the contract (docs/http_agents.md).

Run it, then evaluate it:  solarchain-eval evaluate --policies mine=http://127.0.0.1:8000/act
Each step the benchmark POSTs {"observation": [...], "observation_names": [...], "hour", "hour_of_day",
"step", "episode", "episode_seed", "run_seed"} and reads {"action": [reward, liquidity, burn]}: three
numbers in [0, 1] (a discrete agent answers {"action": k}, 0 <= k < 125).
"""

import argparse
import contextlib
import json
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer


def decide(obs: dict) -> list:
    """Pay less and hold more liquidity when spare supply is thin (the gap's median on the paper's data
    is 1.36, never below 0); burn more in hours with many violating records (the median rate is 0.08)."""
    short = obs["supply_gap"] < 1.0
    reward = 0.2 if short else 0.5
    liquidity = 0.95 if short or obs["liquidity"] < 1.0 else 0.4
    burn = 0.8 if obs["raw_physics_record_rate"] > 0.08 else 0.1
    return [reward, liquidity, burn]


class AgentHandler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"  # keep-alive: one connection serves the whole evaluation
    disable_nagle_algorithm = True  # send each reply at once (no ~40 ms wait for a delayed ACK)
    constant = None  # --constant: this action every step instead of decide()

    def do_POST(self):
        length = int(self.headers.get("Content-Length", 0))
        body = self.rfile.read(length)  # read the whole request, so the next one starts clean
        if self.path != "/act":
            return self.reply(404, {"error": "POST the step to /act"})
        try:
            request = json.loads(body)
            obs = dict(zip(request["observation_names"], request["observation"], strict=True))
        except (ValueError, KeyError, TypeError) as error:
            return self.reply(400, {"error": f"bad request: {error}"})
        self.reply(200, {"action": self.constant or decide(obs)})

    def reply(self, status, answer):
        data = json.dumps(answer).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(data)))  # lets the client keep the connection
        self.end_headers()
        self.wfile.write(data)

    def log_message(self, format, *args):  # quiet: a line per step would flood the terminal
        pass


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8000, help="0: any free port (the URL printed names it)")
    parser.add_argument("--constant", help="answer this action every step, e.g. 0.3333,0.7333,0.1")
    args = parser.parse_args()
    if args.constant:
        AgentHandler.constant = [float(v) for v in args.constant.split(",")]
    server = ThreadingHTTPServer((args.host, args.port), AgentHandler)
    print(f"agent listening on http://{args.host}:{server.server_address[1]}/act", flush=True)
    with contextlib.suppress(KeyboardInterrupt):  # Ctrl-C stops it quietly
        server.serve_forever()
