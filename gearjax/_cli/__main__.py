"""``python -m gearjax._cli``: the console script."""

from .app import console

console()
