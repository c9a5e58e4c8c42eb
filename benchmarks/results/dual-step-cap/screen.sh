#!/bin/sh
# Regenerates cap-<CAP>.jsonl (run from this directory; CAP 0 = IPOPT's rule, 0.01 = default).
for cap in 0 0.01 0.1; do
  for spec in "iiwa-com 100 0" "iiwa-distance 100 0" "drone 100 0" "drone-limits 100 0" \
      "chain4 1 0" "chain16 1 0" "chain64 1 0" "chain4-obstacle 1 0" "chain8-obstacle 1 0" \
      "chain16-obstacle 1 0" "chain32-obstacle 1 0" "chain64-obstacle 1 0"; do
    python screen.py $spec $cap
  done > cap-$cap.jsonl
done
