"""Files of the commands: input files read the one way every command reads them, and outputs that fail.

A YAML input (a parameter file, a scenario) is parsed by :func:`load_yaml`: PyYAML's safe loader, except that
a key given twice in one mapping is an error naming it; plain YAML keeps the last and drops the first without
a word, so a repeated ``/**:`` section or a repeated ``m:`` would silently lose what it set.

A path on the command line can name anything: a FIFO (reading it waits for a writer that never comes), a
device (``/dev/zero`` never ends), a directory, a file of gigabytes or of bytes that are not text.
:func:`read_input` reads only a regular file of at most :data:`MAX_INPUT_BYTES`, as UTF-8; anything else is a
:class:`~moose.params.ParamError` naming the file, before a single byte of a special file is read.

Output paths are checked before any work starts (:mod:`moose.cli.common`); what can still fail is writing
after the work is done, on a full disk: :class:`OutputError`.  The command then reports its result first and
the failed output after it, with an exit status of its own (:data:`moose.verdict.EXIT_OUTPUT`).
"""
from __future__ import annotations

import contextlib
import os
import stat
from pathlib import Path
from typing import Any, Iterator

import yaml

from .errors import ParamError

MAX_INPUT_BYTES = 256 * 1024
"""The largest input file read (256 KiB).  The shipped parameter file is 3 kB and a scenario 0.5 kB, so this is
about 80 times the largest hand-written input; PyYAML's parser takes about 3 s per MiB here, and a larger file is
refused before it is parsed or held in memory."""


class OutputError(RuntimeError):
    """An output could not be written after the work was done (a full disk, an I/O error); the message names the
    output, the reason and what was kept."""


_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def read_input(path: str | Path, what: str) -> str:
    """The text of the input file ``path`` (``what`` names it in errors: "parameter file", "scenario file").

    The file is opened without blocking (a FIFO does not wait for a writer), checked to be a regular file
    through the descriptor that was opened, and read up to :data:`MAX_INPUT_BYTES`; its bytes must be UTF-8.
    """
    where = f"{what} {str(path)!r}"
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        raise ParamError(f"{where} cannot be read: {exc.strerror or exc}") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            kind = next((name for test, name in _KINDS if test(mode)), "a special file")
            raise ParamError(f"{where} cannot be read: it is {kind}, not a regular file")
        data = os.read(fd, MAX_INPUT_BYTES + 1)
        while len(data) <= MAX_INPUT_BYTES and (more := os.read(fd, MAX_INPUT_BYTES + 1 - len(data))):
            data += more
    except OSError as exc:
        raise ParamError(f"{where} cannot be read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if len(data) > MAX_INPUT_BYTES:
        raise ParamError(f"{where} is larger than {MAX_INPUT_BYTES} bytes (moose.files.MAX_INPUT_BYTES): "
                         "not an input file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ParamError(f"{where} is not UTF-8 text: byte 0x{data[exc.start]:02x} at offset {exc.start}") from None


@contextlib.contextmanager
def replaced_atomically(path: Path) -> Iterator[Path]:
    """A temporary file next to ``path`` (same suffix, so writers that go by it choose the same format) that
    replaces ``path`` once the block has written it; if writing fails the temporary file is removed and
    ``path`` is left as it was, never half written."""
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key given twice in one mapping (a merge key ``<<`` may still be
    overridden: that is what it is for)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            line = key_node.start_mark.line + 1
            try:
                if key in seen:
                    raise _DuplicateKey(key, seen[key], line)
            except TypeError:  # an unhashable key: the safe loader reports it below
                break
            seen[key] = line
        return super().construct_mapping(node, deep=deep)


class _DuplicateKey(yaml.YAMLError):
    def __init__(self, key: Any, first: int, again: int) -> None:
        super().__init__(f"{key!r} is given twice in one mapping (lines {first} and {again}); "
                         "YAML would keep the second and drop the first without a word")


def load_yaml(text: str, where: str) -> Any:
    """The YAML document ``text`` (read by :func:`read_input`), parsed safely; ``where`` names it in errors
    ("parameter file 'p.yaml'").  Invalid YAML and a key given twice in one mapping are a
    :class:`~moose.params.ParamError` naming ``where``."""
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)
    except _DuplicateKey as exc:
        raise ParamError(f"{where}: {exc}") from None
    except yaml.YAMLError as exc:
        raise ParamError(f"{where} is not valid YAML: {exc}") from None


_DUMPER: Any = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
"""libyaml's emitter where PyYAML was built with it (its wheels are), else PyYAML's own: the same document,
about four times faster (a 15 kB ``metadata.yaml``: 2.8 against 12.4 ms), the lines of a long string folded
elsewhere."""


def dump_yaml(data: Any, sort_keys: bool = False) -> str:
    """``data`` as a YAML document of plain types (``yaml.safe_dump``'s), keys in their order unless ``sort_keys``."""
    return yaml.dump(data, Dumper=_DUMPER, sort_keys=sort_keys)
