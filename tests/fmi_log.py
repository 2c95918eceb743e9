"""FMI 2.0 callbacks (fmpy's allocator, a logger that keeps every message) for tests that drive an FMU
through fmpy's low-level classes and assert on what it logged."""
import fmpy
from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)


class Log:
    """Logger callbacks that record (status, category, message)."""

    def __init__(self):
        self.messages = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)

    def _log(self, env, name, status, category, message):
        self.messages.append((status, category.decode(), message.decode()))

    def text(self, status=None) -> str:
        """Every message (of ``status`` only, if given), one a line."""
        return "\n".join(m for s, _, m in self.messages if status is None or s == status)

    def last(self) -> str:
        return self.messages[-1][2] if self.messages else ""
