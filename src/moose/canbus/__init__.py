"""The FPEV2-Kanon vehicle bus (500 kbit/s): DBC codec, command safety, bus load, bridge and vehicle-ECU cores.

Pure logic with time passed in; the python-can I/O is in :mod:`moose.canbus.bus`.
"""
