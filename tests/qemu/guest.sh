#!/bin/sh
# Runs inside the QEMU guest, chrooted into the host's root file system (read-only 9p).
# $1: frame file to send; $2: the repository root. Prints one "QEMU-USB-RESULT:" line.
FRAMES="$1"; REPO="$2"
PY="$REPO/.venv/bin/python"
export PYTHONDONTWRITEBYTECODE=1 PYTHONHASHSEED=0 HOME=/run TMPDIR=/run NUMBA_CACHE_DIR=/run
echo "QEMU-USB-STEP: guest up $(cat /proc/uptime)"
"$PY" -c "import numpy" > /run/py.log 2>&1 && echo "QEMU-USB-STEP: python+numpy $(cat /proc/uptime)" \
  || { tail -5 /run/py.log | sed 's/^/QEMU-USB-STEP: python: /'; ls -la "$PY" | sed 's/^/QEMU-USB-STEP: /'; }
result() { echo "QEMU-USB-RESULT: $*"; }
G=/sys/kernel/config/usb_gadget/cnc
mkdir -p $G || { result "fail configfs"; exit 1; }
echo 0x1209 > $G/idVendor; echo 0x0001 > $G/idProduct
mkdir -p $G/strings/0x409 $G/configs/c.1/strings/0x409 $G/functions/ffs.cnc
echo cnc-interp > $G/strings/0x409/manufacturer
echo "FPGA emulator" > $G/strings/0x409/product
echo 0001 > $G/strings/0x409/serialnumber
echo stream > $G/configs/c.1/strings/0x409/configuration
ln -s $G/functions/ffs.cnc $G/configs/c.1/
mkdir -p /run/ffs && mount -t functionfs cnc /run/ffs || { result "fail functionfs"; exit 1; }
echo "QEMU-USB-STEP: device start $(cat /proc/uptime)"; "$PY" "$REPO/tests/qemu/ffs_device.py" /run/ffs /run/device.json > /run/device.log 2>&1 &
i=0; while [ ! -e /run/ffs/ep1 ] && [ $i -lt 300 ]; do sleep 1; i=$((i+1)); done
[ -e /run/ffs/ep1 ] || { sed 's/^/QEMU-USB-STEP: device: /' /run/device.log; result "fail device program"; exit 1; }
echo "QEMU-USB-STEP: device ready $(cat /proc/uptime)"; ls /sys/class/udc | head -1 > $G/UDC
i=0; while [ ! -e /dev/bus/usb/001/002 ] && [ $i -lt 100 ]; do sleep 0.1; i=$((i+1)); done
"$PY" - "$FRAMES" <<'PYEOF'
import json, sys, time
from cnc_interp.fpga.commands import send_frame_file
t = time.time()
rep = send_frame_file(sys.argv[1], "1209:0001")
dt = time.time() - t
time.sleep(0.5)
dev = json.load(open("/run/device.json"))
print("QEMU-USB-LINK:", json.dumps({"frames": rep.frames_sent, "bytes": rep.bytes_sent,
      "retries": rep.retries, "timeouts": rep.timeouts, "polls": rep.status_polls,
      "host_bytes_accepted": rep.final.bytes_accepted, "seconds": round(dt, 2)}))
print("QEMU-USB-DEVICE:", json.dumps(dev))
PYEOF
rc=$?
[ $rc -eq 0 ] || { sed 's/^/QEMU-USB-STEP: device: /' /run/device.log; result "fail host rc=$rc"; exit 1; }
result "done"
