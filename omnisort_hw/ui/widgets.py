"""Small pieces every page uses: test names on elements, and the confirmation dialog."""

from __future__ import annotations

from typing import TypeVar

from nicegui import ui
from nicegui.element import Element

E = TypeVar("E", bound=Element)


def tag(element: E, name: str) -> E:
    """Name an element for the tests: a marker for the simulated user, an attribute for a
    real browser."""
    element.mark(name).props(f"data-test={name}")
    return element


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


def number_input(label: str, name: str, value: float | None = None) -> ui.input:
    """A number typed as text, named `name` for the tests: read it with
    `schema_form.typed_number`, so that what is not a number reaches the schema's check as
    typed (a browser's number field reports it as empty, which means the default)."""
    return tag(ui.input(label, value="" if value is None else f"{value:g}"), name)
