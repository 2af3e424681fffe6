"""The expert's geometry on synthetic boxes and regions, without LIBERO: footprints, the
placement choice and best spot, a drawer's clearance, grasp choice for upright and lying
objects and wide rims, put-aside spots and what stands in the way (`boxworld.BoxWorld`
answers the questions `SimEnv` would)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.policies.scripted import placement
from pipeline.policies.scripted.grasps import plan_grasp
from pipeline.policies.scripted.hand import closing_axis
from pipeline.policies.scripted.placement import (HAND_SPAN, REGION_INSIDE, best_spot, clearance_counter,
                                                  is_long_footprint, no_walls, place_choice, region_half,
                                                  turned_box, widths)
from pipeline.policies.scripted.recovery import checks
from pipeline.sim.facts import Box, Region
from tests.policies.boxworld import TABLE_TOP, BoxWorld, box, drawer, standing


def rect_corners(centre, size) -> np.ndarray:
    c, h = np.asarray(centre, dtype=float), np.asarray(size, dtype=float) / 2
    return np.array([[c[0] + sx * h[0], c[1] + sy * h[1]] for sx in (-1, 1) for sy in (-1, 1)])


def plain_region(centre=(0.1, 0.2), half=(0.1, 0.08)) -> Region:
    return Region(pos=np.array([*centre, TABLE_TOP + 0.005]), mat=np.eye(3), size=np.array([*half, 0.005]),
                  parent="table", joints=())


# ---- footprints ------------------------------------------------------------------------------
def test_a_footprint_turned_a_quarter_swaps_length_and_width_and_its_offset_turns_with_it():
    body = np.array([1.0, 1.0])
    size, centre = turned_box(rect_corners(body + [0.03, 0.0], [0.2, 0.05]), body, np.pi / 2)
    assert size == pytest.approx([0.05, 0.2])
    assert centre == pytest.approx([0.0, 0.03])


def test_a_long_footprint_is_long_and_a_square_one_is_not():
    assert is_long_footprint(rect_corners([0, 0], [0.2, 0.05]))
    assert not is_long_footprint(rect_corners([0, 0], [0.06, 0.06]))
    w = widths(rect_corners([0, 0], [0.2, 0.05]))
    assert len(w) == 36 and min(w) == pytest.approx(0.05) and w[0] == pytest.approx(0.2)


def test_a_regions_half_extent_follows_its_rotation():
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    r = Region(pos=np.zeros(3), mat=quarter, size=np.array([0.1, 0.05, 0.02]), parent=None)
    assert region_half(r) == pytest.approx([0.05, 0.1, 0.02])


# ---- best spot -------------------------------------------------------------------------------
def test_an_empty_region_is_used_at_its_centre():
    r = plain_region()
    key, spot = best_spot(r, region_half(r), r.pos[:2], [], np.array([0.06, 0.06]), None, no_walls, -1)
    assert key == (0, 0.0) and spot == pytest.approx(r.pos[:2])


def test_a_crowded_region_gives_the_spot_beside_what_stands_there_but_inside_the_region():
    r = plain_region()
    half = region_half(r)
    pot = Box(np.array([0.0, 0.1, TABLE_TOP]), np.array([0.12, 0.3, TABLE_TOP + 0.1]))  # on the left part
    size = np.array([0.08, 0.08])
    key, spot = best_spot(r, half, r.pos[:2], [pot], size, None, no_walls, -1)
    lo, hi = spot - size / 2, spot + size / 2
    overlap = np.prod(np.clip(np.minimum(hi, pot.hi[:2]) - np.maximum(lo, pot.lo[:2]), 0, None))
    assert spot[0] > r.pos[0]  # away from the pot
    assert np.all(np.abs(spot - r.pos[:2]) <= REGION_INSIDE * half[:2] + 1e-12)  # LIBERO's `On` sees it inside
    assert key[1] == pytest.approx(100 * overlap + np.linalg.norm(spot - r.pos[:2]))


def test_in_a_drawer_the_nearest_spot_with_no_blocked_cell_wins_on_a_fine_grid_along_the_slide():
    r = Region(pos=np.array([0.0, 0.0, 1.0]), mat=np.eye(3), size=np.array([0.1, 0.1, 0.04]), parent="c",
               joints=("slide",))
    wall_from = 0.013  # everything at x below this is blocked (a front wall, say)
    key, spot = best_spot(r, region_half(r), r.pos[:2], [], np.array([0.05, 0.05]), None,
                          lambda p: int(p[0] < wall_from), fine=0)
    grid = r.pos[0] + 0.1 * np.linspace(-1, 1, 41)  # 41 points along the slide (x)
    assert key[0] == 0 and spot[0] == pytest.approx(grid[grid >= wall_from].min()) and spot[1] == 0.0


# ---- a drawer's clearance --------------------------------------------------------------------
def grid(half=0.1, step=0.005):
    xs = np.arange(-half, half + step, step)
    return xs, xs.copy()


def test_cells_under_an_overhang_and_on_a_thin_wall_are_blocked_and_the_open_middle_is_not():
    xs, ys = grid()
    floor = 1.0
    heights = np.full((len(xs), len(ys)), np.nan)
    heights[xs > 0.07, :] = floor + 0.05  # an overhang over the back
    wall = np.array([[[-0.081, -0.1, floor], [-0.08, 0.1, floor + 0.05]]])  # 1 mm: thinner than the grid
    edge, shift = np.array([0.024, 0.024]), np.zeros(2)
    blocked = clearance_counter(xs, ys, heights, floor, wall, np.zeros(2), np.array([0.1, 0.1]), edge, shift,
                                None, 0.005)
    assert blocked(np.array([0.0, 0.0])) == 0
    assert blocked(np.array([0.06, 0.0])) > 0  # reaches under the overhang
    assert blocked(np.array([-0.07, 0.0])) > 0  # on the wall
    assert blocked(np.array([0.06, 0.0])) > blocked(np.array([0.05, 0.0]))  # the more under it, the more cells


def test_a_turned_footprint_also_counts_cells_off_the_drawer_and_under_the_hands_housing():
    xs, ys = grid(0.2)
    floor = 1.0
    heights = np.full((len(xs), len(ys)), np.nan)
    heights[:, ys > 0.12] = floor + 0.1  # the cabinet's face beside the drawer, higher than HOUSING_Z
    half, edge = np.array([0.1, 0.1]), np.array([0.03, 0.03])
    kw = dict(floor=floor, part_boxes=np.empty((0, 2, 3)), centre=np.zeros(2), half=half, edge=edge,
              shift=np.zeros(2), step=0.005)
    as_lies = clearance_counter(xs, ys, heights, size=None, **kw)
    turned = clearance_counter(xs, ys, heights, size=np.array([0.2, 0.06]), **kw)  # long along x: housing along y
    assert as_lies(np.array([0.0, 0.0])) == 0 and turned(np.array([0.0, 0.0])) == 0
    assert as_lies(np.array([0.0, 0.05])) == 0 < turned(np.array([0.0, 0.05]))  # housing reaches the face
    assert as_lies(np.array([0.09, 0.0])) == 0 < turned(np.array([0.09, 0.0]))  # footprint off the drawer


# ---- placement choice on a scene -------------------------------------------------------------
def drawer_world(overhang_from: float | None = None, inner=(0.1, 0.1), height=0.08, obj=(0.12, 0.12, 0.05)):
    region, joint, name = drawer("drawer", [0.1, 0.0, 1.0], inner, height=height)
    cabinet = list(joint[1])
    if overhang_from is not None:  # the drawer above, over the back of this one
        cabinet.append(box([0.1 + overhang_from + 0.1, 0.0, 1.0 + height + 0.03], [0.2, 0.4, 0.02]))
    return BoxWorld(objects={"bowl": [standing([-0.1, 0.3], obj)]}, fixtures={"cabinet_1": cabinet},
                    regions={"drawer_region": region}, joints={name: joint})


def test_an_object_goes_into_the_middle_of_a_clear_drawer():
    s = drawer_world().scene()
    xy, blocked, turn = place_choice(s, "bowl", "drawer_region")
    assert blocked == 0 and turn == 0.0 and xy == pytest.approx([0.1, 0.0])


def test_an_object_is_kept_clear_of_the_drawer_above_that_overhangs_the_back():
    s = drawer_world(overhang_from=0.06).scene()
    xy, blocked, turn = place_choice(s, "bowl", "drawer_region")
    assert blocked == 0 and turn == 0.0
    assert 0.1 - 0.04 < xy[0] < 0.1  # pulled to the front, still between the walls
    assert placement.place_room(s, "bowl", "drawer_region")


def test_a_drawer_with_no_room_for_the_object_says_so():
    s = drawer_world(overhang_from=0.0).scene()  # overhang over half the drawer: a 12 cm bowl fits nowhere
    _, blocked, _ = place_choice(s, "bowl", "drawer_region")
    assert blocked > 0 and not placement.place_room(s, "bowl", "drawer_region")


def test_a_long_object_that_fits_nowhere_as_it_lies_is_turned_along_the_drawer():
    region, joint, name = drawer("drawer", [0.1, 0.0, 1.0], (0.12, 0.06), height=0.06)
    w = BoxWorld(objects={"bottle": [standing([-0.1, 0.3], [0.06, 0.18, 0.06])]},  # lying across the drawer
                 fixtures={"cabinet_1": list(joint[1])}, regions={"drawer_region": region}, joints={name: joint})
    s = w.scene()
    xy, blocked, turn = place_choice(s, "bottle", "drawer_region")
    assert blocked == 0 and abs(turn) == pytest.approx(np.pi / 2)
    size, _ = placement.turned_foot(s, "bottle", turn)
    assert size[0] > size[1]  # its length now runs along the drawer
    assert max(HAND_SPAN, size[1]) / 2 < 0.06  # with the fingers across it, between the side walls


def test_a_region_on_a_body_or_the_table_is_aimed_at_its_centre_and_the_support_ceiling_depends_on_drawers():
    w = drawer_world()
    w.objects["plate"] = [standing([0.0, -0.3], [0.16, 0.16, 0.02])]
    w.regions["table_region"] = plain_region((0.3, 0.3))
    s = w.scene()
    assert place_choice(s, "bowl", "plate") == (pytest.approx([0.0, -0.3]), 0, 0.0)
    assert place_choice(s, "bowl", "table_region")[0] == pytest.approx([0.3, 0.3])
    top = 1.0 + 0.08
    assert placement.support_ceiling(w, "drawer_region") == pytest.approx(top)  # its top itself
    assert placement.support_ceiling(w, "table_region") == pytest.approx(TABLE_TOP + 0.01 + 0.03)
    assert placement.support_ceiling(w, "plate") == np.inf
    dest = placement.destination(s, "bowl", "plate")
    assert dest == pytest.approx([0.0, -0.3, TABLE_TOP + 0.02])  # on the plate's top


# ---- grasp choice ------------------------------------------------------------------------------
def test_an_upright_bottle_is_grasped_across_its_narrowest_side_at_mid_height_with_the_least_wrist_turn():
    s = BoxWorld(objects={"bottle": [standing([0.0, 0.1], [0.06, 0.06, 0.2])]}).scene()
    g = plan_grasp(s, "bottle")
    assert not g.rim and g.yaw == 0.0
    assert g.pos == pytest.approx([0.0, 0.1, TABLE_TOP + 0.1])
    again = plan_grasp(s, "bottle", choice=1)  # a retry: the other way round
    assert again.yaw == pytest.approx(-np.pi / 2) and again.pos == pytest.approx(g.pos)


def test_a_lying_bottle_is_grasped_across_it_at_its_centre_of_mass_not_its_middle():
    body = box([-0.03, 0.1, TABLE_TOP + 0.03], [0.14, 0.06, 0.06])  # x from -0.1 to 0.04
    neck = box([0.07, 0.1, TABLE_TOP + 0.03], [0.06, 0.03, 0.03])  # to 0.1
    w = BoxWorld(objects={"bottle": [body, neck]})
    g = plan_grasp(w.scene(), "bottle")
    assert not g.rim and g.yaw == 0.0  # fingers close along y, across it
    com = w.object_com("bottle")
    assert g.pos[0] == pytest.approx(com[0]) and g.pos[0] < 0.0  # towards the heavy body, off its middle (0.0)
    assert g.pos[2] == pytest.approx(TABLE_TOP + 0.03)


def test_a_wide_bowl_is_grasped_by_its_rim_where_the_outer_finger_lands_clear():
    bowl = standing([0.0, 0.0], [0.16, 0.16, 0.05])
    alone = plan_grasp(BoxWorld(objects={"bowl": [bowl]}).scene(), "bowl")
    assert alone.rim and alone.yaw == 0.0 and alone.pos == pytest.approx([0.0, -0.068, TABLE_TOP + 0.03])
    # a carton beside the bowl where that outer finger would land: the other side
    w = BoxWorld(objects={"bowl": [bowl], "carton": [standing([0.0, -0.12], [0.06, 0.04, 0.15])]})
    g = plan_grasp(w.scene(), "bowl")
    assert g.rim and g.pos[1] == pytest.approx(0.068)
    assert checks.tip_blockers(w.scene(), "bowl", alone, set()) == ["carton"]
    assert checks.tip_blockers(w.scene(), "bowl", g, set()) == []


def test_the_palms_ends_see_a_neighbour_standing_where_they_come_down():
    s = BoxWorld(objects={"box": [standing([0.0, 0.0], [0.05, 0.05, 0.03])],
                          "carton": [standing([0.0, 0.09], [0.05, 0.03, 0.2])]}).scene()
    g = plan_grasp(s, "box")
    # the palm reaches ~10 cm along the closing axis: a yaw closing along y would land on the carton
    assert abs(closing_axis(g.yaw)[1]) < 0.5
    straight = type(g)(pos=g.pos, yaw=0.0, rim=False)
    assert checks.grasp_blockers(s, "box", straight, set()) == ["carton"]
    assert checks.grasp_blockers(s, "box", straight, {"carton"}) == []


# ---- put aside ---------------------------------------------------------------------------------
def square(xy, r) -> np.ndarray:
    return np.array([[xy[0] - r, xy[1] - r, 0.0], [xy[0] + r, xy[1] + r, 0.0]])


def test_a_put_aside_spot_is_near_the_hand_in_front_of_the_robot_and_clear_of_everything():
    w = BoxWorld(objects={"cup": [standing([0.2, 0.3], [0.06, 0.06, 0.1])]})
    s = w.scene()
    first = checks.free_spot(s, "cup", [])
    base = w.robot_base()[:2]
    assert 0.42 - 1e-9 <= first[0] - base[0] <= 0.7 and abs(first[1] - base[1]) <= 0.3 + 1e-9
    r = float(np.linalg.norm([0.06, 0.06])) / 2 + 0.03
    w.objects["tin"] = [standing(first, [0.08, 0.08, 0.1])]  # something now stands there
    second = checks.free_spot(w.scene(), "cup", [])
    tin = w.object_boxes("tin")[0]
    assert not (np.all(tin[0, :2] <= second + r) and np.all(second - r <= tin[1, :2]))
    # a goal target near the best spot pushes the spot away from it
    away = checks.free_spot(w.scene(), "cup", [np.array([*second, 0.0])])
    assert np.linalg.norm(away - second) > 0.05


def test_a_put_aside_spot_keeps_off_a_forbidden_box_and_none_is_found_on_a_full_table():
    w = BoxWorld(objects={"cup": [standing([0.2, 0.3], [0.06, 0.06, 0.1])]})
    base = w.robot_base()[:2]
    best = checks.free_spot(w.scene(), "cup", [])
    sweep = square(best, 0.1)  # an opening drawer's sweep over it
    spot = checks.free_spot(w.scene(), "cup", [], forbid=[sweep])
    r = float(np.linalg.norm([0.06, 0.06])) / 2 + 0.03
    assert spot is not None and np.abs(spot - best).max() > 0.1 + 0.05 + r  # (0.05: the forbidden pad)
    w.objects["tray"] = [box([*(base + [0.56, 0.0]), TABLE_TOP + 0.01], [0.6, 0.8, 0.02])]
    assert checks.free_spot(w.scene(), "cup", []) is None


def test_what_lies_on_the_object_or_stands_at_its_destination_is_in_the_way_unless_kept():
    w = BoxWorld(objects={"bowl": [standing([0.0, 0.0], [0.12, 0.12, 0.05])],
                          "lid": [box([0.0, 0.0, TABLE_TOP + 0.06], [0.08, 0.08, 0.02])],
                          "mug": [standing([0.3, 0.0], [0.08, 0.08, 0.1])],
                          "far": [standing([-0.3, -0.3], [0.05, 0.05, 0.1])]})
    s = w.scene()
    dest = np.array([0.3, 0.0, TABLE_TOP])
    assert checks.blockers(s, "bowl", dest, set()) == ["lid", "mug"]
    assert checks.blockers(s, "bowl", dest, {"mug"}) == ["lid"]
