"""pylsl, imported on demand, and resolving the streams to record."""

from __future__ import annotations

import configparser
import contextlib
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

FILTER_KEYS = ("name", "type", "source_id")


class LslError(RuntimeError):
    """LSL is missing or a stream cannot be resolved / opened (one line for the command)."""


#: liblsl's configuration when the user has none: its defaults, logging warnings and errors only (liblsl's log
#: levels: 0 info, -1 warning, -2 error, -3 fatal), so that its "Loaded default config" info line is not printed
QUIET_CONFIG = "[log]\nlevel = -1\n"
_configured = False


def user_config_files(cwd: Path | None = None, home: Path | None = None) -> list[Path]:
    """The liblsl configuration files the user has, in liblsl's order of search: ``$LSLAPICFG`` (when set, even
    if missing: liblsl then reports it), ``lsl_api.cfg`` in the working directory, ``~/lsl_api/lsl_api.cfg``,
    ``/etc/lsl_api/lsl_api.cfg``."""
    cwd = Path.cwd() if cwd is None else cwd
    home = Path.home() if home is None else home
    found = [Path(os.environ["LSLAPICFG"])] if os.environ.get("LSLAPICFG") else []
    candidates = (cwd / "lsl_api.cfg", home / "lsl_api" / "lsl_api.cfg", Path("/etc/lsl_api/lsl_api.cfg"))
    return found + [p for p in candidates if p.is_file()]


#: the settings that decide which streams a resolver can see: (section, key, liblsl's default)
SCOPE_SETTINGS = (
    ("lab", "SessionID", "default"),
    ("multicast", "ResolveScope", "site"),
    ("ports", "MulticastPort", "16571"),
    ("ports", "BasePort", "16572"),
)


def config_summary(files: list[Path] | None = None) -> str:
    """Which LSL configuration applies and its settings that decide what is visible (session, scope, ports),
    for an error that finds no stream: ``lsl_api.cfg: SessionID x, ResolveScope machine, ...`` or liblsl's
    defaults. ``files``: :func:`user_config_files` (the first readable one is liblsl's)."""
    files = user_config_files() if files is None else files
    source = next((f for f in files if f.is_file()), None)
    parser = configparser.ConfigParser(inline_comment_prefixes=(";", "#"), strict=False)
    parser.optionxform = str  # liblsl's keys are case-sensitive
    if source is not None:
        try:
            parser.read(source, encoding="utf-8")
        except (configparser.Error, UnicodeDecodeError):
            return f"LSL configuration {source} (not readable as INI)"
    settings = ", ".join(f"{key} {parser.get(sec, key, fallback=default)}" for sec, key, default in SCOPE_SETTINGS)
    return f"LSL configuration {source if source is not None else 'liblsl defaults'}: {settings}"


def pylsl() -> Any:
    """The pylsl module (its wheels bundle liblsl); LslError naming the extra when it is not installed.

    Without a configuration file of the user's (:func:`user_config_files`), liblsl is given :data:`QUIET_CONFIG`
    before its first use: its defaults, with its info lines ("Loaded default config" on every run) left out and
    its warnings and errors kept. A user's own file (``LSLAPICFG`` or liblsl's usual places) is used as it is,
    its ``[log] level`` included."""
    global _configured
    try:
        import pylsl as module
    except (ImportError, RuntimeError) as exc:  # pylsl raises RuntimeError when liblsl cannot be loaded
        raise LslError(f"live capture needs pylsl with liblsl: pip install 'imulog[lsl]' ({exc})") from None
    if not _configured:
        _configured = True
        setter = getattr(module, "set_config_content", None)  # pylsl >= 1.17.7 with liblsl >= 1.17.7
        if setter is not None and not user_config_files():
            with contextlib.suppress(NotImplementedError):  # an older liblsl: its info line stays
                setter(QUIET_CONFIG)
    return module


@dataclass(frozen=True)
class StreamFilter:
    """``name=EMG``, ``type=IMU`` or ``source_id=xio-1234``: which stream(s) to record."""

    key: str
    value: str

    @classmethod
    def parse(cls, text: str) -> StreamFilter:
        key, sep, value = text.partition("=")
        key = key.strip()
        if not sep or key not in FILTER_KEYS or not value.strip():
            raise ValueError(f"{text!r} is not {'=, '.join(FILTER_KEYS)}=VALUE")
        return cls(key, value.strip())

    def matches(self, info: Any) -> bool:
        return str(getattr(info, self.key)()) == self.value

    def __str__(self) -> str:
        return f"{self.key}={self.value}"


def describe(info: Any) -> str:
    """One line for the listing of a resolved stream."""
    rate = info.nominal_srate()
    rate_text = f"{rate:g} Hz" if rate > 0 else "irregular"
    return (
        f"{info.name()} (type {info.type() or '-'}, {info.channel_count()} x {_format_name(info)}, {rate_text}, "
        f"source_id {info.source_id() or '-'}, host {info.hostname() or '-'})"
    )


def _format_name(info: Any) -> str:
    names = {1: "float32", 2: "double64", 3: "string", 4: "int32", 5: "int16", 6: "int8", 7: "int64"}
    return names.get(info.channel_format(), str(info.channel_format()))


def resolve(filters: list[StreamFilter], wait_s: float, poll_s: float = 0.25) -> list[Any]:
    """The streams to record (StreamInfo objects, by uid, in order of discovery).

    Without filters: every stream visible within ``wait_s`` seconds (the full wait: LSL cannot know that no more
    will appear). With filters: every stream that matches one, returned as soon as each filter has matched at
    least one stream; LslError naming the filters still unmatched when ``wait_s`` passes.
    """
    lsl = pylsl()
    deadline = time.monotonic() + max(wait_s, 0.0)
    if not filters:
        found = lsl.resolve_streams(max(wait_s, 0.5))
        if not found:
            raise LslError(
                f"no LSL stream found within {wait_s:g} s (is the source running on this network? {config_summary()})"
            )
        return _unique(found)
    resolver = lsl.ContinuousResolver(forget_after=max(wait_s, 5.0))
    try:
        while True:
            found = [i for i in resolver.results() if any(f.matches(i) for f in filters)]
            missing = [f for f in filters if not any(f.matches(i) for i in found)]
            if not missing:
                time.sleep(min(poll_s, max(deadline - time.monotonic(), 0.0)))  # late siblings of a match
                found = [i for i in resolver.results() if any(f.matches(i) for f in filters)]
                return _unique(found)
            if time.monotonic() >= deadline:
                seen = resolver.results()
                listing = "; ".join(describe(i) for i in seen) or f"none; {config_summary()}"
                raise LslError(
                    f"no LSL stream matches {', '.join(map(str, missing))} within {wait_s:g} s (visible: {listing})"
                )
            time.sleep(poll_s)
    finally:
        del resolver


def shared_names(infos: list[Any]) -> list[str]:
    """One line per stream name that several of ``infos`` have (other programs' streams, another device of the
    same model): the streams with their source_id and host, and how to pick one."""
    lines = []
    names = [i.name() for i in infos]
    for name in dict.fromkeys(n for n in names if names.count(n) > 1):
        same = [i for i in infos if i.name() == name]
        where = "; ".join(f"source_id {i.source_id() or '-'} on host {i.hostname() or '-'}" for i in same)
        lines.append(
            f"{len(same)} streams are named {name} ({where}): all are recorded; to record one, pick it with "
            "--stream source_id=..."
        )
    return lines


def _unique(infos: list[Any]) -> list[Any]:
    seen: set[str] = set()
    out = []
    for info in infos:
        if info.uid() not in seen:
            seen.add(info.uid())
            out.append(info)
    return out
