"""Advice sources: where the advice PARE shapes with comes from, one module per mode."""

from pirl.pare.sources.async_ import AsyncSource
from pirl.pare.sources.base import AdviceSource, SourceSetup
from pirl.pare.sources.student import StudentSource
from pirl.pare.sources.sync import SyncSource

SOURCES: dict[str, type[StudentSource] | type[SyncSource] | type[AsyncSource]] = {
    source.mode: source for source in (StudentSource, SyncSource, AsyncSource)
}
"""The sources by ``pare.mode``."""

__all__ = ["SOURCES", "AdviceSource", "AsyncSource", "StudentSource", "SourceSetup", "SyncSource"]
