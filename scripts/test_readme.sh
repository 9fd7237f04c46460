#!/usr/bin/env bash
# Runs every command the README shows for real hardware, against the virtual controller instead
# of /dev/ttyACM0, so the README cannot rot. `make demo` and `make test` are covered by the demo
# test and by CI itself. Usage: scripts/test_readme.sh BIN_DIR WORK_DIR
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
export PATH="$1:$PATH"
work=$2
mkdir -p "$work" && cd "$work"
# A virtual sensor at 512 px (fast to render), boards and the rig as a user would capture them.
omni-sim sensor --preset paper --width 512 -o truth >/dev/null
cp "$root/testdata/boards/board_9x6.json" board.json
omni-sim boards --camera truth/camera.json --board board.json --count 12 --seed 3 --out boards >/dev/null
omni-sim rig --camera truth/camera.json --scanner truth/scanner.json --board board.json --angles 15 --out rig_capture >/dev/null
cp rig_capture/rig.json rig.json
cp rig_capture/pose.png pose.png
# A fresh virtual controller per command renders the rig; its camera buffers frames, so scans
# wait for them.
emulator=
start_emulator() {
  rm -f emulator.port
  # The idealised sensor: at 512 px the realistic stripe on the rig boards is too dim and
  # speckled for the light-plane fit (this checks the commands, not the accuracy).
  omni-trigger emulate --buffered-camera --ideal --camera truth/camera.json --scanner truth/scanner.json \
    --scene rig_capture/scene.json --frames frames > emulator.port 2>> emulator.log &
  emulator=$!
  for _ in $(seq 1 100); do [ -s emulator.port ] && break; sleep 0.1; done
  port=$(head -n 1 emulator.port)
}
trap 'kill $emulator 2>/dev/null || true' EXIT
export FRAME_TIMEOUT_MS=600000 RIG_ANGLES=15:23:1 ANGLES=15:23:1
# The README's commands: inline `omni-…`/`scripts/…` code spans and the ```sh block of the
# hardware section, with the port replaced and scans given the emulator's frame timeout.
python3 - "$root/README.md" > commands.sh <<'PY'
import re, sys
text = open(sys.argv[1]).read()
section = text.split("## Calibrate and scan with real hardware")[1].split("\n## ")[0]
cmds = []
for block in re.findall(r"```sh\n(.*?)```", section, re.S):
    cmds.append(re.sub(r"\\\n\s*", "", block).strip())
for span in re.findall(r"`((?:omni-|scripts/)[^`]+)`", section):
    if " " in span:
        cmds.append(span)
order = lambda c: (0 if c.startswith("omni-trigger info") else 1 if c.startswith("omni-calib-receiver") else
                   2 if "calibrate.sh" in c else 3 if "scan.sh" in c else 4)
for c in sorted(cmds, key=order):
    print(c)
PY
n=0
while IFS= read -r cmd; do
  start_emulator
  cmd=${cmd//\/dev\/ttyACM0/$port}
  cmd=${cmd//omni-trigger scan --port $port/omni-trigger scan --port $port --frame-timeout-ms 600000 --facets 0}
  cmd=${cmd//--angles 0:30:0.25/--angles 15:23:1}
  cmd=${cmd//scripts\//$root/scripts/}
  echo "README> $cmd" >&2
  mkdir -p scan
  bash -euo pipefail -c "$cmd" >/dev/null
  kill "$emulator" 2>/dev/null || true
  wait "$emulator" 2>/dev/null || true
  n=$((n + 1))
done < commands.sh
echo "test_readme.sh: $n README commands ran" >&2
[ "$n" -ge 6 ]
