"""The CDR of the DDS path's message classes, compiled per type: what cyclonedds-python's ``serialize`` and
``deserialize`` compute for XCDR1 little-endian (what rmw_cyclonedds sends), about ten times faster.

cyclonedds-python interprets a type's layout field by field at every write and take (75 µs to write a
``nav_msgs/msg/Odometry``, 130 µs to read it, on this machine): in the lockstep graph that was about a third of
each node's CPU time per tick.  :func:`install` gives each class built by :func:`moose_ros.interfaces.message_class`
a serialiser and a deserialiser generated from the same definitions (the ``.msg`` files and rosbags' ROS 2 Jazzy
store), as rosbags does for its own classes: the primitive fields between two variable-length fields (strings,
sequences) are one ``struct`` format per alignment of their start (XCDR1 aligns a primitive of n bytes to n, at
most 8, counted from the end of the 4-byte encapsulation header), so a message is a few ``pack`` calls.

Anything else is cyclonedds-python's own code: XCDR2 or big-endian data, a serialiser asked for another version
or buffer, and a message the compiled serialiser cannot write (a value of the wrong type or range, a sequence
over its bound, a fixed array of the wrong length), so that such a message fails as it always did.
``tests/test_cdr.py`` compares both with cyclonedds-python and rosbags on every type of the store.
"""
from __future__ import annotations

import struct
from typing import Any, Callable, Optional

from rosbags.interfaces import Nodetype

HEADER = b"\x00\x01\x00\x00"
"""The encapsulation header of XCDR1 little-endian plain CDR (``CDR_LE``), what the compiled code reads and writes."""
FORMATS = {"bool": "?", "byte": "B", "char": "B", "int8": "b", "uint8": "B", "int16": "h", "uint16": "H",
           "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q", "float32": "f", "float64": "d"}
"""``struct`` codes of the base types (byte and char are uint8 on the wire, as in rmw_cyclonedds)."""
_PAD = tuple(bytes(n) for n in range(8))


class Unsupported(ValueError):
    """A message the compiled serialiser does not write (cyclonedds-python's then does, or raises as it did)."""


def _size(code: str) -> int:
    return struct.calcsize("<" + code)


class _Compiler:
    """Python source of ``_ser_<T>(m, o)`` (append ``m``'s CDR to the bytearray ``o``, whose byte 4 is offset 0)
    and ``_des_<T>(d, p)`` (the message at offset ``p`` of ``d`` and the offset after it) for every type reached
    from the first one compiled."""

    def __init__(self, fielddefs: dict[str, Any], classes: Callable[[str], type[Any]]) -> None:
        self.fielddefs = fielddefs
        self.classes = classes
        self.names: dict[str, str] = {}
        self.env: dict[str, Any] = {"_PAD": _PAD, "_pack": struct.pack, "_unpack": struct.unpack_from,
                                    "Unsupported": Unsupported}
        self.source: list[str] = []
        self.counter = 0

    def name(self, type_name: str) -> str:
        if type_name not in self.names:
            self.names[type_name] = type_name.replace("/", "_")
            self._compile(type_name)
        return self.names[type_name]

    def _struct(self, codes: list[tuple[str, int]]) -> str:
        """Structs packing ``codes`` (code, count) from each start offset modulo 8; returns their name."""
        self.counter += 1
        name = f"_S{self.counter}"
        variants = []
        for start in range(8):
            offset, fmt = start, "<"
            for code, count in codes:
                align = min(_size(code), 8)
                pad = -offset % align
                fmt += "x" * pad + (f"{count}{code}" if count != 1 else code)
                offset += pad + _size(code) * count
            variants.append(struct.Struct(fmt))
        self.env[name] = tuple(variants)
        return name

    def _flatten(self, type_name: str, path: str) -> list[tuple[Any, ...]]:
        """The fields of ``type_name`` in wire order, nested messages inlined: (kind, node, expression)."""
        out: list[tuple[Any, ...]] = []
        for field, node in self.fielddefs[type_name][1]:
            expr = f"{path}.{field}"
            kind, detail = node
            if kind == Nodetype.NAME:
                self.name(detail)  # its class, for the constructor of the inlined fields
                out += self._flatten(detail, expr)
            elif kind == Nodetype.BASE and detail[0] != "string":
                out.append(("prim", FORMATS[detail[0]], 1, expr))
            elif kind == Nodetype.ARRAY and detail[0][0] == Nodetype.BASE and detail[0][1][0] != "string":
                out.append(("prim", FORMATS[detail[0][1][0]], detail[1], expr))
            else:
                out.append(("var", node, expr))
        return out

    def _tree(self, type_name: str, values: list[str]) -> str:
        """The constructor expression of ``type_name`` from the local variables ``values`` (consumed in order)."""
        args = []
        for _field, node in self.fielddefs[type_name][1]:
            args.append(self._tree(node[1], values) if node[0] == Nodetype.NAME else values.pop(0))
        return f"_C_{self.names[type_name]}({', '.join(args)})"

    def _compile(self, type_name: str) -> None:
        own = self.names[type_name]
        items = self._flatten(type_name, "m")
        ser = [f"def _ser_{own}(m, o):"]
        des = [f"def _des_{own}(d, p):"]
        values: list[str] = []
        run: list[tuple[Any, ...]] = []

        def flush() -> None:
            if not run:
                return
            codes = [(code, count) for _kind, code, count, _expr in run]
            name = self._struct(codes)
            args = ", ".join(expr if count == 1 else f"*{expr}" for _kind, _code, count, expr in run)
            ser.append(f"    o += {name}[(len(o) - 4) & 7].pack({args})")
            des.append(f"    s = {name}[(p - 4) & 7]; t = s.unpack_from(d, p); p += s.size")
            index = 0
            for _kind, code, count, _expr in run:
                var = f"v{len(values)}"
                values.append(var)
                kind = "bytes" if code == "B" else "list"  # cyclonedds-python reads an octet array as bytes
                part = f"t[{index}]" if count == 1 else f"{kind}(t[{index}:{index + count}])"
                des.append(f"    {var} = {part}")
                index += count
            run.clear()

        for item in items:
            if item[0] == "prim":
                run.append(item)
                continue
            flush()
            var = f"v{len(values)}"
            values.append(var)
            self._variable(item[1], item[2], var, ser, des, "    ")
        flush()
        ser.append("    return o")
        des.append(f"    return {self._tree(type_name, values)}, p")
        self.source += ser + des

    def _variable(self, node: tuple[Any, Any], expr: str, var: str, ser: list[str], des: list[str],
                  indent: str) -> None:
        """A string, sequence, or array of strings or messages: ``expr`` written, ``var`` read."""
        kind, detail = node
        if kind == Nodetype.BASE:  # a string (its bound is not in the class: cyclonedds-python writes it all)
            ser += [f"{indent}b = {expr}.encode()",
                    f"{indent}o += _PAD[-(len(o) - 4) & 3]; o += _pack('<I', len(b) + 1); o += b; o += b'\\0'"]
            des += [f"{indent}p += -(p - 4) & 3; n = _unpack('<I', d, p)[0]; p += 4",
                    f"{indent}{var} = str(d[p:p + n - 1], 'utf-8'); p += n"]
            return
        if kind == Nodetype.NAME:
            own = self.name(detail)
            ser.append(f"{indent}_ser_{own}({expr}, o)")
            des.append(f"{indent}{var}, p = _des_{own}(d, p)")
            return
        element, size = detail
        if kind == Nodetype.SEQUENCE:
            bound_check = [f"{indent}if len({expr}) > {size}: raise Unsupported('over bound')"] if size else []
            ser += [*bound_check, f"{indent}o += _PAD[-(len(o) - 4) & 3]; o += _pack('<I', len({expr}))"]
            des += [f"{indent}p += -(p - 4) & 3; n = _unpack('<I', d, p)[0]; p += 4"]
            count = "n"
        else:
            ser.append(f"{indent}if len({expr}) != {size}: raise Unsupported('array length')")
            count = str(size)
        if element[0] == Nodetype.BASE and element[1][0] != "string":
            code = FORMATS[element[1][0]]
            width = _size(code)
            align = f"_PAD[-(len(o) - 4) & {min(width, 8) - 1}]"
            ser.append(f"{indent}if {expr}: o += {align}; o += _pack(f'<{{len({expr})}}{code}', *{expr})")
            des += [f"{indent}if {count}: p += -(p - 4) & {min(width, 8) - 1}",
                    f"{indent}{var} = list(_unpack(f'<{{{count}}}{code}', d, p)); p += {width} * {count}"]
            return
        level = len(indent) // 4
        item, element_var = f"e{level}", f"x{level}"
        ser.append(f"{indent}for {item} in {expr}:")
        self._variable(element, item, "_", ser, [], indent + "    ")
        des += [f"{indent}{var} = []", f"{indent}for _ in range({count}):"]
        self._variable(element, "_", element_var, [], des, indent + "    ")
        des.append(f"{indent}    {var}.append({element_var})")

    def functions(self, type_name: str, cls: type[Any]) -> tuple[Callable[..., Any], Callable[..., Any]]:
        """The serialiser and deserialiser of ``type_name``, whose class is ``cls`` (the classes of the types it
        contains are built before it)."""
        own = self.name(type_name)
        self.env[f"_C_{own}"] = cls
        for other, name in self.names.items():
            if f"_C_{name}" not in self.env:
                self.env[f"_C_{name}"] = self.classes(other)
        if self.source:
            exec(compile("\n".join(self.source), f"<moose_ros.cdr {type_name}>", "exec"), self.env)
            self.source = []
        return self.env[f"_ser_{own}"], self.env[f"_des_{own}"]


_COMPILER: Optional[_Compiler] = None


def install(cls: type[Any], type_name: str, fielddefs: dict[str, Any], classes: Callable[[str], type[Any]]) -> None:
    """Give ``cls`` (the ``IdlStruct`` of ``type_name``) the compiled ``serialize`` and ``deserialize``;
    ``classes`` builds the class of a nested type (:func:`moose_ros.interfaces.message_class`)."""
    global _COMPILER
    if _COMPILER is None or _COMPILER.fielddefs is not fielddefs:
        _COMPILER = _Compiler(fielddefs, classes)
    slow_serialize, slow_deserialize = cls.serialize, cls.deserialize.__func__
    if bytes(slow_serialize(cls()))[:4] != HEADER:  # not XCDR1 by default: cyclonedds-python's code only
        return
    ser, des = _COMPILER.functions(type_name, cls)

    def serialize(self: Any, buffer: Any = None, endianness: Any = None, use_version_2: Optional[bool] = None) -> bytes:
        if buffer is None and endianness is None and not use_version_2:
            try:
                out = ser(self, bytearray(HEADER))
            except (Unsupported, struct.error, TypeError, AttributeError, UnicodeError, OverflowError):
                pass  # cyclonedds-python's own code writes it, or raises as it did
            else:
                return bytes(out)
        return slow_serialize(self, buffer=buffer, endianness=endianness, use_version_2=use_version_2)

    def deserialize(kind: type[Any], data: bytes, has_header: bool = True,
                    use_version_2: Optional[bool] = None) -> Any:
        if has_header and use_version_2 is None and data[:2] == HEADER[:2]:
            return des(data, 4)[0]
        return slow_deserialize(kind, data, has_header=has_header, use_version_2=use_version_2)

    cls.serialize = serialize
    cls.deserialize = classmethod(deserialize)
