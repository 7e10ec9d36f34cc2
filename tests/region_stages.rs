//! The stages run region by region (`talus::contact::RegionStages`) give the whole-stage
//! results bit for bit: the force loop, each law's contacts listed by the region of their
//! first grain in dense order and the lists' runs of rows evaluated in turn, and the force
//! sums, each region's grains summing the rows that touch them (those of the regions from
//! the lowest whose rows reach it up to its own) from the last row to the first. The same
//! scenes, whose energies are not booked (the only steps the region loop serves), end with
//! the same grains, the same contacts (geometry, force, torques, tangential spring) and the
//! same energies and contact count, with regions of many sizes. Between the contact-table
//! sorts (every 20 steps) the contacts made in recycled and appended rows sit outside their
//! region's run of rows, so each region is evaluated in several runs.

use crate::common;
use crate::lane_forms::{chute_text, run_with};

use talus::collision::ContactIndex;
use talus::contact::regions::RegionRuns;
use talus::contact::{Contact, ContactBodies, RegionStages};
use talus::core::prelude::*;
use talus::core::regions::{GrainRegions, REGION_GRAINS};

/// Runs `steps` steps of a scene, region by region with regions of `region_grains` grains
/// or (`None`) stage by stage over the whole packing ([`run_with`]).
fn run(
    text: &str,
    steps: u64,
    region_grains: Option<usize>,
) -> (impl PartialEq + std::fmt::Debug, usize) {
    run_with(text, steps, move |world| {
        if let Some(region_grains) = region_grains {
            world.insert_resource(RegionStages { region_grains });
        }
    })
}

/// Asserts that a scene without the energy ledger ends the same with the force loop run
/// region by region, for each region size, as in table order.
fn same_by_region(what: &str, text: &str, steps: u64, region_sizes: &[usize]) {
    assert!(
        text.contains("energy_ledger: false"),
        "{what}: the region loop serves only steps whose energies are not booked"
    );
    let (in_order, contacts) = run(text, steps, None);
    assert!(contacts > 0, "{what}: the grains must touch");
    for &region_grains in region_sizes {
        let (by_region, _) = run(text, steps, Some(region_grains));
        assert!(
            by_region == in_order,
            "{what}: regions of {region_grains} grains changed the results"
        );
    }
}

#[test]
fn the_chute_flow_is_the_same_region_by_region() {
    // 59 steps: the last force loops run 19 steps after a sort, their regions in many
    // runs; regions of 500 grains are 64 regions of under a cell layer each (800 grains).
    same_by_region("chute", &chute_text(), 59, &[500, 16_384, 1 << 20]);
}

#[test]
fn a_settling_pile_in_a_box_is_the_same_region_by_region() {
    // Grain–wall contacts belong to their grain's region.
    let text = common::settling_box_scene("regions-box", 2000).replace(
        "output: (recording: false)",
        "output: (recording: false, energy_ledger: false)",
    );
    same_by_region("settling box", &text, 2000, &[1, 7, 64]);
}

/// The runs of rows of each region (`talus::contact::regions::RegionRuns`, regions of
/// [`REGION_GRAINS`]) in the contact tables after `steps` steps of the chute, and the
/// contacts, with ended contacts handed to new pairs by region or in table order alone,
/// and those left over kept as vacant rows or despawned (`despawn`).
fn region_runs_after(steps: u64, in_table_order: bool, despawn: bool) -> (usize, usize) {
    let (mut sim, _) = common::build(&chute_text());
    {
        let mut index = sim.world.resource_mut::<ContactIndex>();
        index.handout_in_table_order = in_table_order;
        index.despawn_unused = despawn;
    }
    sim.prime().unwrap();
    sim.run_steps(steps).unwrap();
    let snapshot = sim.world.resource::<GrainSnapshot>().clone();
    let regions = GrainRegions::new(snapshot.len(), REGION_GRAINS);
    let mut q = sim.world.query::<(&Contact, &ContactBodies)>();
    let mut runs = RegionRuns::default();
    let (mut count, mut contacts) = (0, 0);
    for (c, d) in q
        .query(&sim.world)
        .contiguous_iter()
        .expect("contact query is dense")
    {
        runs.build(&regions, &snapshot, c, d, &[]);
        count += runs.all().len();
        contacts += c.iter().filter(|c| !c.is_vacant()).count();
    }
    assert!(regions.count() >= 2, "the chute spans more than one region");
    (count, contacts)
}

#[test]
fn new_contacts_take_ended_rows_of_their_own_region() {
    // 19 steps after the sort at step 20 the table has drifted furthest from its order.
    let (in_table_order, contacts) = region_runs_after(39, true, true);
    let (by_region, _) = region_runs_after(39, false, true);
    let (vacant_rows, same_contacts) = region_runs_after(39, false, false);
    assert!(contacts > 10_000);
    assert_eq!(contacts, same_contacts, "the same flow");
    eprintln!(
        "runs of rows: {in_table_order} handed out in table order, {by_region} by region, \
         {vacant_rows} by region with vacant rows kept"
    );
    // Right after a sort each region is one run; a contact made out of its region's run
    // splits it in three. Handed out by region, contacts spawned past the table's end and
    // those a despawn moves into a freed row still land outside their region's run: with
    // the chute's two regions 684 runs against 942 (in the 512,000-grain replica, 32
    // regions, about 20,000 against 60,000 ten steps after a sort).
    assert!(
        by_region < in_table_order,
        "runs of rows by region: {by_region} handed out by region, {in_table_order} in table order"
    );
    // With the rows of ended contacts kept vacant, and a share of vacant rows given to
    // each region at each sort, new contacts find rows in their own region.
    assert!(
        vacant_rows * 10 < by_region,
        "runs of rows by region: {vacant_rows} with vacant rows, {by_region} without"
    );
}

/// The narrow phase hands ended contacts to new pairs region by region, the regions in
/// parallel, and enters what each region's pairs took in region order, which is the
/// pairs' order: the chute (two regions of [`REGION_GRAINS`]) ends the same, grains,
/// contacts and energies, through two contact-table sorts, as with one job over every
/// region, and on 1, 2 and 3 threads.
#[test]
fn the_chute_hands_out_contacts_alike_by_region_and_on_any_number_of_threads() {
    let text = chute_text();
    let on = |threads: usize, one_job: bool| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            run_with(&text, 59, move |world| {
                world.resource_mut::<ContactIndex>().handout_in_one_job = one_job;
            })
        })
    };
    let (one_job, contacts) = on(2, true);
    assert!(contacts > 10_000, "the chute flows with its contacts");
    for threads in [1, 2, 3] {
        let (by_region, _) = on(threads, false);
        assert!(
            by_region == one_job,
            "the handout by region on {threads} threads changed the results"
        );
    }
}
