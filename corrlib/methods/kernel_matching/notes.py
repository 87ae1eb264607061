"""What the user is told about a kernel-matching result (the CLI and the studio show these notes).
"""

from __future__ import annotations


def copies_note(extras: dict) -> str | None:
    """What the user is told when finer meshes were matched on remeshed copies (``mesh_vertices``), else None."""
    if not extras or "matched_on" not in extras:
        return None
    n_x, n_y = extras["matched_on"]
    return (f"matched on copies remeshed to {n_x} and {n_y} vertices and carried to every vertex by the final steps "
            f"(mesh_vertices; 0 matches at full resolution, slower)")


def turn_note(extras: dict) -> str | None:
    """What the user is told when the map, or some of its limbs, was turned by the target's reflection
    (:mod:`.reorientation`), else None."""
    if not extras:
        return None
    said = []
    if extras.get("turned"):
        said.append(f"the map sent left to right on most of the shape (orientation agreement "
                    f"{extras['agreement_before_turn']:.2f}); it was composed with an intrinsic "
                    f"reflection (agreement now {extras['orientation_agreement']:.2f})")
    if extras.get("turned_regions"):
        count = extras["turned_regions"]
        said.append(f"{count} region{'s' if count > 1 else ''} (a protrusion with the body beside it) matched "
                    f"mirror-inverted {'were' if count > 1 else 'was'} turned by a reflection (a mirrored pair by the "
                    f"source's or the target's, whichever is nearer an isometry; a limb crossed onto another limb's "
                    f"image by the target's)")
    if extras.get("turned_parts"):
        count = extras["turned_parts"]
        said.append(f"{count} protrusion{'s' if count > 1 else ''} (limbs) matched to the mirror-image limb "
                    f"{'were' if count > 1 else 'was'} turned by the target's reflection")
    if extras.get("released_regions"):
        said.append(f"{extras['released_regions']} regions (a mirror pair of limbs with the body beside them) were "
                    f"matched swapped, each onto the other's mirror image; they were matched again with the rest "
                    f"of the map as landmarks")
    declined = extras.get("declined_turns") or {}
    if any(declined.values()):
        what = [f"{declined[key]} {name}{'s' if declined[key] > 1 else ''}" for key, name in
                (("turned_regions", "turned region"), ("turned_parts", "turned limb"),
                 ("released_regions", "released region")) if declined.get(key)]
        said.append(f"the orientation stage turned or released parts of the map ({', '.join(what)}), but the map "
                    f"optimised after that was farther from an isometry (geodesic distortion "
                    f"{extras['distortion_after_turns']:.4f} against {extras['distortion_before_turns']:.4f} "
                    f"√area), so the map as found before those turns was kept")
    if extras.get("swapped_regions"):
        said.append(f"{extras['swapped_regions']} regions (a mirror pair of limbs with the body beside them) are "
                    f"matched swapped, each onto the other's mirror image, and were left as found (kernel matching "
                    f"matches such limbs again from the rest of the map)")
    if extras.get("replaced_part"):
        distortions = extras["disagreement_distortions"]
        said.append(f"two parts of the map disagreed (the geodesic distances between them distorted "
                    f"{extras['disagreement_ratio']:.1f}× as much as within them); {extras['replaced_part']} source "
                    f"vertices were matched again with the rest of the map as landmarks (geodesic distortion "
                    f"{distortions[0]:.4f} → {min(distortions[1:]):.4f} √area)")
    combined = extras.get("combined_starts") or {}
    if combined.get("kept"):
        distortions = combined["distortions"]
        said.append(f"the two starts' maps were each right on a part of the shape: {combined['taken']} source "
                    f"vertices took the other start's partners, and the map optimised from that combination "
                    f"replaced the kept one (geodesic distortion {distortions[0]:.4f} → {distortions[3]:.4f} "
                    f"√area)")
    if not said:
        return None
    again = "; the turned map was then optimised once more" if "first_pass" in extras and (
        extras.get("turned") or extras.get("turned_regions") or extras.get("turned_parts")) else ""
    return "; ".join(said) + again + " (reorient=false keeps the map as found)"


def start_note(extras: dict) -> str | None:
    """What the user is told about the start of a map: for ``init="best"``, that the functional map's start
    was kept (``extras["init"] == "fmap"``, with the measures that kept it, :func:`~.starts.kept_start`) or failed
    (``extras["other_start_error"]``); for a refined map, that its own start lost to the descriptor assignment
    (``extras["start"] == "descriptors"``, :func:`~.seed_stage.choose_start`); else None (the descriptor start kept, as
    usual)."""
    if extras and extras.get("other_start_error"):
        return (f"the functional map's start failed ({extras['other_start_error']}), so the map is the descriptor "
                "start's alone")
    if extras and extras.get("init") == "fmap" and extras.get("start_measures"):
        from corrlib.methods.kernel_matching.starts import reverses_where_other_keeps

        kept, other = extras["start_measures"]["fmap"], extras["start_measures"]["descriptors"]
        if reverses_where_other_keeps(other, kept):
            energy_ratio = other["energy"] / kept["energy"]
            return ("of the two starts the functional map's was kept: the descriptor start's map reversed "
                    f"orientation on most of the shape (orientation agreement {other['agreement']:.2f} against "
                    f"{kept['agreement']:.2f}), which neither its kernel energy ({energy_ratio:.4f}× the functional "
                    f"map's) nor its geodesic distortion ({other['distortion']:.4f} against "
                    f"{kept['distortion']:.4f} √area) can see")
        return ("of the two starts the functional map's was kept, its map being better by every measure: kernel "
                f"energy {kept['energy'] / other['energy']:.4f}× the descriptor start's, orientation agreement "
                f"{kept['agreement']:.2f} against {other['agreement']:.2f}, geodesic distortion "
                f"{kept['distortion']:.4f} against {other['distortion']:.4f} √area")
    if not extras or extras.get("start") != "descriptors":
        return None
    return ("the given map reached a lower kernel objective than the method's own start (the descriptor "
            "assignment) at the first time, so the refinement continued from the descriptor assignment; the given "
            "partners stand only where the result lies within the smallest kernel's width of them, or where they are "
            "the more isometric partner")


def reversal_note(extras: dict) -> str | None:
    """A warning when a map reverses orientation on most of the shape (its
    :func:`~.passes.orientation_agreement`, ``extras["orientation_agreement"]``, is negative: left matched to
    right), else None. The kernel energy cannot see this (a reflection of a symmetric shape keeps every heat
    kernel), so it is said with the result rather than left to the user's eye."""
    agreement = extras.get("orientation_agreement") if extras else None
    if agreement is None or not agreement < 0:
        return None
    return (f"the map reverses orientation on most of the shape (orientation agreement {agreement:.2f} < 0: left "
            "matched to right); try landmarks (--init), or check the target is not a mirror image")
