"""The recording description of a URDF robot measured on several tips or with coupled joints: a
`RobotDescription` whose movable joints are the tree's read joints (every joint of the chains
root → tips but the coupled ones, in `UrdfTree.joint_names` order), for the importers' readers and
the recording's joint order."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from pipeline.errors import RobocalError


def tree_description(urdf: Path, root: str, tips: list[str], coupled: list[str]):
    """(description of the read joints, {coupled joint: {terms, offset}} for the campaign) of the chains
    `root` → each of `tips` of the URDF file, joints coupled by `--coupled` texts and the URDF's `<mimic>`."""
    try:
        text = Path(urdf).read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise RobocalError(f"{urdf}: cannot read URDF ({e.__class__.__name__}: {e})") from None
    return tree_description_text(text, str(urdf), root, tips, coupled)


def tree_description_text(text: str, urdf: str, root: str, tips: list[str], coupled: list[str]):
    """`tree_description` of a URDF text (`urdf` names where it came from, for the messages)."""
    from pipeline.models import urdf as urdf_mod
    from pipeline.models.coupling import check_coupling, check_units, parse_coupling
    from pipeline.models.urdf_tree import UrdfTree

    descs = tuple(urdf_mod.parse(text, root, t, source=str(urdf), allow_mimic=True) for t in tips)
    types = {j.name: j.type for d in descs for j in d.movable}
    movable = set(types)
    cp = {c: v for c, v in urdf_mod.mimic_couplings(text, str(urdf)).items() if c in movable}
    check_coupling(cp, movable, f"{urdf}: <mimic>", types)
    given = {}
    for text_c in coupled:
        c, t, o = parse_coupling(text_c)
        if c not in movable:
            raise RobocalError(f"--coupled {c!r}: not a movable joint of the chains {root} → {', '.join(tips)}")
        check_units(text_c, types)
        check_coupling({c: (t, o)}, movable, f"--coupled {text_c!r}", types)
        cp[c] = given[c] = (t, o)
    check_coupling(cp, movable, "--coupled")
    tree = UrdfTree(descs, coupled=tuple((c, tuple(sorted(t.items())), o) for c, (t, o) in sorted(cp.items())))
    read = set(tree.joint_names)
    desc = replace(descs[0], joints=tuple(j for j in tree.all_joints if j.name in read))
    return desc, {c: {"terms": t, "offset": o} for c, (t, o) in given.items()}
