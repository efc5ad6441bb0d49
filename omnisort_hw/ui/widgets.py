"""Small pieces every page uses: test names on elements, and the confirmation dialog."""

from __future__ import annotations

from typing import Any, TypeVar

from nicegui import ui

E = TypeVar("E")


def tag(element: E, name: str) -> E:
    """Name an element for the tests: a marker for the simulated user, an attribute for a
    real browser."""
    el: Any = element
    return el.mark(name).props(f"data-test={name}")


async def confirm(text: str) -> bool:
    """Ask for an explicit confirmation; True only on the confirm button."""
    with ui.dialog() as dialog, ui.card():
        ui.label(text)
        with ui.row():
            tag(ui.button("Confirm", on_click=lambda: dialog.submit(True)), "confirm")
            tag(ui.button("Cancel", on_click=lambda: dialog.submit(False)).props("flat"), "cancel")
    result = await dialog
    dialog.clear()
    return result is True
