"""The AEC view of a parallel env, with clear errors where PettingZoo's converter asserts."""

from __future__ import annotations

from typing import Any

from pettingzoo.utils.conversions import parallel_to_aec_wrapper


class FdiaAECEnv(parallel_to_aec_wrapper):
    """PettingZoo's ``parallel_to_aec_wrapper`` that fails loudly on misuse.

    ``step`` before ``reset`` raises ``RuntimeError`` (the converter raises ``AttributeError``);
    ``step`` once every agent is done raises ``RuntimeError`` (the converter raises a bare
    ``AssertionError`` and leaves the env unusable); a done agent's action must be None, as
    PettingZoo's AEC protocol requires, else ``ValueError``. The env stays usable after each
    error: nothing changes before the checks pass.
    """

    def reset(self, seed: int | None = None, options: dict | None = None) -> None:
        """Reset the parallel env and the agent order."""
        super().reset(seed=seed, options=options)

    def step(self, action: Any) -> None:
        """Store ``action`` for the selected agent; step the parallel env after the last one."""
        if not hasattr(self, "_observations"):
            raise RuntimeError("step() called before reset(): call reset() first")
        if not self.agents:
            raise RuntimeError(
                "step() called after the episode ended (every agent is done): call reset()"
            )
        agent = self.agent_selection
        if (self.terminations[agent] or self.truncations[agent]) and action is not None:
            raise ValueError(
                f"agent {agent!r} is done: its action must be None (PettingZoo's AEC protocol), "
                f"got {action!r}"
            )
        super().step(action)

    def render(self, mode: str | None = None) -> Any:
        """Delegate to the parallel env (``mode`` as in its ``render``)."""
        return self.env.render(mode)
