#!/usr/bin/env bash
# The README's main job: brickcastd on its embedded default (loopback, no token, generated
# volumes) and brickcast-client flying an orbit through it, switching the transfer function
# half-way. Leaves brickcast-demo/frames/*.png, the client's latency summary
# (brickcast-demo/latency.txt) and the daemon's log (brickcast-demo/brickcastd.log).
set -euo pipefail
cd "$(dirname "$0")/.."
out=brickcast-demo
mkdir -p "$out"
rm -f "$out/port" "$out/web-port"
./build/tools/brickcastd --listen 127.0.0.1:0 --port-file "$out/port" \
  --web-port-file "$out/web-port" 2>"$out/brickcastd.log" &
daemon=$!
trap 'kill -TERM "$daemon" 2>/dev/null || true' EXIT
for _ in $(seq 1 600); do
  [ -s "$out/port" ] && break
  kill -0 "$daemon" 2>/dev/null || { cat "$out/brickcastd.log"; exit 1; }
  sleep 0.1
done
port=$(cat "$out/port")
echo "main job: the browser viewer is at http://127.0.0.1:$(cat "$out/web-port")/ while it runs"
./build/tools/brickcast-client --port "$port" --volume phantom --frames 36 --size 256,256 \
  --tf ct-skin --tf-switch ct-bone@18 -o "$out/frames" --save-every 6 | tee "$out/latency.txt"
kill -TERM "$daemon"
wait "$daemon"
trap - EXIT
echo "main job: frames in $out/frames, latency summary in $out/latency.txt, daemon log in $out/brickcastd.log"
