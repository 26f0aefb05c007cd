"""The model variants of the paper (Sec. 5.2) as configuration of one inference routine.

Only variants whose stages exist are registered; each names the switches it turns on.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable


@dataclass(frozen=True)
class Variant:
    """Switches of the scene model.

    Attributes
    ----------
    name : str
        Name used on the command line and in tables (paper notation).
    shared_plane : bool
        All objects stand on one ground plane (``+gp``).
    fine : bool
        Fit the deformable wireframe (``fg``) instead of stopping at coarse 3D boxes.
    searched_occluder : bool
        Search occluder masks from missing part evidence (``+so``).
    deterministic_occlusion : bool
        Derive inter-object occlusion by ray casting (``+do``).

    Examples
    --------
    >>> VARIANTS["full"]
    Variant(name='full', shared_plane=True, fine=True, searched_occluder=True, deterministic_occlusion=True)
    >>> [v.name for v in VARIANTS.values() if not v.fine]
    ['coarse', 'coarse+gp']
    """

    name: str
    shared_plane: bool
    fine: bool = False
    searched_occluder: bool = False
    deterministic_occlusion: bool = False


VARIANTS: dict[str, Variant] = {
    v.name: v
    for v in (
        Variant("coarse", shared_plane=False),
        Variant("coarse+gp", shared_plane=True),
        Variant("fg", shared_plane=False, fine=True),
        Variant("fg+so", shared_plane=False, fine=True, searched_occluder=True),
        Variant("fg+do", shared_plane=False, fine=True, deterministic_occlusion=True),
        Variant("fg+gp", shared_plane=True, fine=True),
        Variant("full", shared_plane=True, fine=True, searched_occluder=True, deterministic_occlusion=True),
    )
}
#: What a fit of one variant fits unless told (`wirescene fit` / `predict`, :func:`wirescene.fit`): the whole model.
DEFAULT_VARIANT = "full"


def get_variant(name: str) -> Variant:
    """The :class:`Variant` of :data:`VARIANTS` named ``name``; a ``ValueError`` listing them
    for any other name.

    Examples
    --------
    >>> get_variant("fg+gp").shared_plane
    True
    >>> get_variant("fast")
    Traceback (most recent call last):
    ...
    ValueError: unknown variant 'fast'; available: coarse, coarse+gp, fg, fg+so, fg+do, fg+gp, full
    """
    try:
        return VARIANTS[name]
    except KeyError:
        raise ValueError(f"unknown variant {name!r}; available: {', '.join(VARIANTS)}") from None


def casts_rays(names: Iterable[str]) -> bool:
    """Whether fitting the variants ``names`` casts rays: the fine stage's occlusion reasoning,
    the work ``--device`` moves to PyTorch, which the coarse variants never do.

    Examples
    --------
    >>> casts_rays(["coarse", "coarse+gp"]), casts_rays(["coarse", "fg"])
    (False, True)
    """
    return any(get_variant(name).fine for name in names)
