"""A pyusb backend that emulates the FPGA controller, with fault injection.

``SimBackend`` subclasses ``usb.backend.IBackend``: ``usb.core.find(backend=...)``,
``set_configuration``, endpoint ``write``/``read`` all go through it to a
``DeviceCore`` (frame parsing, sequencing, golden-model datapath). Faults are
injected on OUT transfers (and IN timeouts) either at given call numbers or at
random with a seed:

- ``timeout``: nothing arrives, ``USBTimeoutError``;
- ``timeout_partial``: the first half of the data arrives, then ``USBTimeoutError``
  (libusb reports a timeout even when part of a transfer went through);
- ``short``: only part of the data is taken, the call returns the short count;
- ``corrupt``: one byte is flipped on the wire, the call reports success;
- ``stall``: the endpoint halts (``USBError`` EPIPE) until ``clear_halt``;
- ``disconnect``: the device vanishes (``USBError`` ENODEV) until ``reconnect()``;
- ``read_timeout``: a status read times out (its answer stays queued: the host
  must then recognise it as stale by its poll id).
"""

from __future__ import annotations

import errno
import random
from dataclasses import dataclass, field
from types import SimpleNamespace

import usb.backend
import usb.core

from ..constants import FPGA_USB_PID, FPGA_USB_VID
from .device import DeviceCore

EP_OUT = 0x01
EP_IN = 0x81
WRITE_FAULTS = ("timeout", "timeout_partial", "short", "corrupt", "stall")


@dataclass
class FaultPlan:
    """Which faults to inject.

    at_write / at_read: {call number (1-based): fault kind} for OUT / IN transfers
    (status polls are OUT transfers too).
    rate: probability of a random fault per OUT transfer, drawn from ``kinds`` with ``seed``.
    """

    at_write: dict = field(default_factory=dict)
    at_read: dict = field(default_factory=dict)
    rate: float = 0.0
    kinds: tuple = WRITE_FAULTS
    read_timeout_rate: float = 0.0
    seed: int = 0
    disconnect_after_seq: int | None = None  # vanish at the first write once this seq is accepted


class SimBackend(usb.backend.IBackend):
    """An emulated USB device with one bulk OUT (0x01) and one bulk IN (0x81) endpoint."""

    def __init__(
        self,
        core: DeviceCore | None = None,
        faults: FaultPlan | None = None,
        vid: int = FPGA_USB_VID,
        pid: int = FPGA_USB_PID,
    ):
        self.core = core or DeviceCore()
        self.faults = faults or FaultPlan()
        self.rng = random.Random(self.faults.seed)
        self.vid, self.pid = vid, pid
        self.connected = True
        self.stalled = False
        self.configuration = 0
        self.writes = 0
        self.reads = 0
        self.injected: list[tuple[int, str]] = []  # (write call, kind) actually injected
        self._dev = object()
        self._dropped_once = False

    # -- fault control ---------------------------------------------------------------------
    def reconnect(self) -> None:
        """Plug the device back in: its state (last sequence, datapath) is kept."""
        self.connected = True
        self.stalled = False

    def _check(self) -> None:
        if not self.connected:
            raise usb.core.USBError("No such device (it may have been disconnected)", -4, errno.ENODEV)

    # -- descriptors ---------------------------------------------------------------------------
    def enumerate_devices(self):
        if self.connected:
            yield self._dev

    def get_device_descriptor(self, dev):
        return SimpleNamespace(
            bLength=18,
            bDescriptorType=1,
            bcdUSB=0x0200,
            bDeviceClass=0xFF,
            bDeviceSubClass=0,
            bDeviceProtocol=0,
            bMaxPacketSize0=64,
            idVendor=self.vid,
            idProduct=self.pid,
            bcdDevice=0x0100,
            iManufacturer=0,
            iProduct=0,
            iSerialNumber=0,
            bNumConfigurations=1,
            address=1,
            bus=1,
            port_number=1,
            port_numbers=(1,),
            speed=3,
        )

    def get_configuration_descriptor(self, dev, config):
        return SimpleNamespace(
            bLength=9,
            bDescriptorType=2,
            wTotalLength=32,
            bNumInterfaces=1,
            bConfigurationValue=1,
            iConfiguration=0,
            bmAttributes=0x80,
            bMaxPower=50,
            extra_descriptors=[],
        )

    def get_interface_descriptor(self, dev, intf, alt, config):
        return SimpleNamespace(
            bLength=9,
            bDescriptorType=4,
            bInterfaceNumber=0,
            bAlternateSetting=0,
            bNumEndpoints=2,
            bInterfaceClass=0xFF,
            bInterfaceSubClass=0,
            bInterfaceProtocol=0,
            iInterface=0,
            extra_descriptors=[],
        )

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        addr = EP_OUT if ep == 0 else EP_IN
        return SimpleNamespace(
            bLength=7,
            bDescriptorType=5,
            bEndpointAddress=addr,
            bmAttributes=2,
            wMaxPacketSize=512,
            bInterval=0,
            bRefresh=0,
            bSynchAddress=0,
            extra_descriptors=[],
        )

    # -- handles -------------------------------------------------------------------------------
    def open_device(self, dev):
        self._check()
        return object()

    def close_device(self, dev_handle):
        pass

    def set_configuration(self, dev_handle, config_value):
        self._check()
        self.configuration = config_value

    def get_configuration(self, dev_handle):
        self._check()
        return self.configuration

    def claim_interface(self, dev_handle, intf):
        self._check()

    def release_interface(self, dev_handle, intf):
        pass

    def clear_halt(self, dev_handle, ep):
        self._check()
        self.stalled = False

    def reset_device(self, dev_handle):
        self._check()
        self.stalled = False

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        self._check()
        return 0 if not hasattr(data, "__len__") else len(data)

    # -- transfers -----------------------------------------------------------------------------
    def _write_fault(self) -> str | None:
        kind = self.faults.at_write.get(self.writes)
        after = self.faults.disconnect_after_seq
        if after is not None and self.core.last_seq >= after and not self._dropped_once:
            self._dropped_once = True
            return "disconnect"
        if kind is None and self.faults.rate > 0 and self.rng.random() < self.faults.rate:
            kind = self.rng.choice(self.faults.kinds)
        return kind

    def bulk_write(self, dev_handle, ep, intf, data, timeout):
        self.writes += 1
        self._check()
        if self.stalled:
            raise usb.core.USBError("Pipe error", -9, errno.EPIPE)
        data = bytes(data)
        kind = self._write_fault()
        if kind:
            self.injected.append((self.writes, kind))
        if kind == "disconnect":
            self.connected = False
            self._check()
        if kind == "stall":
            self.stalled = True
            raise usb.core.USBError("Pipe error", -9, errno.EPIPE)
        if kind == "timeout":
            raise usb.core.USBTimeoutError("Operation timed out", -7, errno.ETIMEDOUT)
        if kind == "timeout_partial":
            self.core.receive(data[: len(data) // 2])
            raise usb.core.USBTimeoutError("Operation timed out", -7, errno.ETIMEDOUT)
        if kind == "short" and len(data) > 1:
            data = data[: self.rng.randint(1, len(data) - 1)]
        if kind == "corrupt" and data:
            i = self.rng.randrange(len(data))
            data = data[:i] + bytes([data[i] ^ (1 << self.rng.randrange(8))]) + data[i + 1 :]
        taken = self.core.receive(data)
        if taken == 0 and data:
            # no room at all: a real device NAKs until the host times out
            raise usb.core.USBTimeoutError("Operation timed out", -7, errno.ETIMEDOUT)
        return taken

    def bulk_read(self, dev_handle, ep, intf, buff, timeout):
        """IN transfer: the next queued STATUS answer, or a timeout when none is queued."""
        self.reads += 1
        self._check()
        kind = self.faults.at_read.get(self.reads)
        if kind is None and self.faults.read_timeout_rate > 0 and self.rng.random() < self.faults.read_timeout_rate:
            kind = "read_timeout"
        if kind == "disconnect":
            self.connected = False
            self._check()
        if kind == "read_timeout" or not self.core.responses:
            raise usb.core.USBTimeoutError("Operation timed out", -7, errno.ETIMEDOUT)
        out = self.core.responses.popleft()
        n = min(len(out), len(buff))
        buff[:n] = type(buff)(buff.typecode, out[:n]) if hasattr(buff, "typecode") else out[:n]
        return n
