"""The FPGA stage (paper 000's trajectory interpolator): fixed point, golden model, frames, USB.

``program`` quantizes a planned program, ``model`` is the bit-exact datapath,
``frames`` the protocol (``docs/fpga-protocol.md``), ``usb_link`` the pyusb host
side, ``device``/``device_sim`` the emulated controller, ``commands`` the CLI
functions. Nothing here is imported by ``import cnc_interp``.
"""
