"""The AEC view of a parallel env, with clear errors where PettingZoo's converter asserts."""

from __future__ import annotations

from typing import Any

from pettingzoo.utils.agent_selector import AgentSelector
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from fdia_env.actions import check_action


class FdiaAECEnv(parallel_to_aec_wrapper):
    """PettingZoo's ``parallel_to_aec_wrapper`` that fails loudly on misuse.

    ``step`` before ``reset`` raises ``RuntimeError`` (the converter raises ``AttributeError``);
    ``step`` once every agent is done raises ``RuntimeError`` (the converter raises a bare
    ``AssertionError`` and leaves the env unusable); a done agent's action must be None, as
    PettingZoo's AEC protocol requires, else ``ValueError``.

    A live agent's action is checked against its action space on that agent's own turn, so a
    bad action raises ``ValueError`` naming the agent that sent it and is not stored (the
    converter stores it and the parallel step refuses it on the last agent's turn, naming the
    first agent, on every retry). Should the parallel step still refuse the round (a rule of
    the game, not of the space), the round restarts from its first agent and the error says
    so. The env stays usable after each error.
    """

    def reset(self, seed: int | None = None, options: dict | None = None) -> None:
        """Reset the parallel env and the agent order."""
        super().reset(seed=seed, options=options)

    def step(self, action: Any) -> None:
        """Store ``action`` for the selected agent; step the parallel env after the last one.

        Raises:
            RuntimeError: Before :meth:`reset` or after the episode ended.
            ValueError: For an action outside the selected agent's action space, a done
                agent's action that is not None, or a round the parallel env refuses.
        """
        if not hasattr(self, "_observations"):
            raise RuntimeError("step() called before reset(): call reset() first")
        if not self.agents:
            raise RuntimeError(
                "step() called after the episode ended (every agent is done): call reset()"
            )
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            if action is not None:
                raise ValueError(
                    f"agent {agent!r} is done: its action must be None (PettingZoo's AEC "
                    f"protocol), got {action!r}"
                )
            super().step(action)
            return
        action = check_action(self.env.action_space(agent), action, agent)
        if not self._agent_selector.is_last():
            super().step(action)
            return
        try:
            super().step(action)
        except Exception as exc:
            self._restart_round()
            exc.add_note(
                f"the round's actions were discarded: agent {self.agent_selection!r} acts again"
            )
            raise

    def _restart_round(self) -> None:
        """Forget the round's stored actions and select its first agent again."""
        for name in self._actions:
            self._actions[name] = None
        self._agent_selector = AgentSelector(self.env.agents)
        self.agent_selection = self._agent_selector.reset()

    def render(self, mode: str | None = None) -> Any:
        """Delegate to the parallel env (``mode`` as in its ``render``)."""
        return self.env.render(mode)


class FdiaOrderEnforcingWrapper(OrderEnforcingWrapper):
    """PettingZoo's ``OrderEnforcingWrapper`` that raises where it asserts or only warns.

    ``step`` before ``reset`` raises ``RuntimeError`` (PettingZoo raises ``AssertionError``),
    and ``step`` after the episode ended raises ``RuntimeError`` (PettingZoo logs a warning
    and returns None, so a loop that forgets to reset runs on silently).
    """

    def step(self, action: Any) -> None:
        """Step the wrapped env; ``RuntimeError`` before ``reset`` or after the episode."""
        if not self._has_reset:
            raise RuntimeError("step() called before reset(): call reset() first")
        if not self.agents:
            raise RuntimeError(
                "step() called after the episode ended (every agent is done): call reset()"
            )
        super().step(action)

    def __str__(self) -> str:
        """As PettingZoo's wrapper prints: the wrapped env's name."""
        return str(self.env)
