"""The FPEV2-Kanon vehicle bus (500 kbit/s, ``config/kanon.dbc``).

Modules, one concept each: ``codec`` (cantools encode/decode, rolling counters, CRC-8 SAE
J1850), ``safety`` (command guard: limits, rate limits, end stops, timeout safe state),
``busload`` (worst-case bus load), ``health`` (error frames, bus states, re-open back-off),
``bridge`` (bridge core), ``ecu`` (vehicle-side ECU emulator core), ``bus`` (python-can
buses by interface name and the thin I/O shell ``BusLink``), ``tools`` (dump and replay).
Everything but ``bus`` and ``tools`` is pure logic with time passed in.
"""
