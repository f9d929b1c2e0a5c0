"""The FPEV2-Kanon vehicle bus (500 kbit/s, ``config/kanon.dbc``).

Modules, one concept each: ``codec`` (cantools encode/decode, rolling counters, CRC-8 SAE
J1850), ``safety`` (command guard: the vehicle's limits, rate limits, end stops, timeout and
minimum-risk maneuver), ``busload`` (worst-case bus load), ``health`` (error frames, bus
states, re-open back-off), ``bridge`` (bridge core), ``ecu`` (vehicle-side ECU emulator core),
``bus`` (python-can buses by interface name and the I/O shell ``BusLink``), ``runner`` (the
bridge as a service: sender thread, bounded receive, diagnostics), ``tools`` (dump and replay).
Everything but ``bus``, ``runner`` and ``tools`` is pure logic with time passed in.
"""
