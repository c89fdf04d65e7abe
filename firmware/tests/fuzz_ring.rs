//! The lock-free ring between the main loop and the interrupts
//! (`firmware::ring`) under proptest: for any interleaving of the two
//! ends, against a `VecDeque` model, every item comes out once, in order,
//! none is lost or invented, a full ring refuses (and hands back) exactly
//! what does not fit, and both ends agree on how many items wait.

use firmware::ring::Ring;
use proptest::prelude::*;
use std::collections::VecDeque;

#[derive(Clone, Copy, Debug)]
enum Step {
    /// The producer offers this item.
    Push(u32),
    /// The consumer takes one (front + release, as the step interrupt does).
    Take,
    /// The consumer peeks, and releases only if told.
    Peek { release: bool },
}

fn steps() -> impl Strategy<Value = Vec<Step>> {
    proptest::collection::vec(
        prop_oneof![
            any::<u32>().prop_map(Step::Push),
            Just(Step::Take),
            any::<bool>().prop_map(|release| Step::Peek { release }),
        ],
        0..400,
    )
}

fn run<const N: usize>(steps: &[Step]) -> Result<(), TestCaseError> {
    let mut ring = Ring::<u32, N>::new();
    let (mut producer, mut consumer) = ring.split();
    let mut model: VecDeque<u32> = VecDeque::new();
    for step in steps {
        match *step {
            Step::Push(item) => {
                let result = producer.enqueue(item);
                if model.len() < N - 1 {
                    prop_assert_eq!(result, Ok(()));
                    model.push_back(item);
                } else {
                    prop_assert_eq!(result, Err(item));
                }
            }
            Step::Take => prop_assert_eq!(consumer.dequeue(), model.pop_front()),
            Step::Peek { release } => {
                prop_assert_eq!(consumer.front().copied(), model.front().copied());
                if release {
                    consumer.release();
                    model.pop_front();
                }
            }
        }
        prop_assert_eq!(producer.len(), model.len());
        prop_assert_eq!(producer.ready(), model.len() < N - 1);
        prop_assert_eq!(consumer.ready(), !model.is_empty());
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn a_ring_of_sixteen_behaves_as_a_queue_of_fifteen(steps in steps()) {
        run::<16>(&steps)?;
    }

    #[test]
    fn a_ring_of_two_behaves_as_a_queue_of_one(steps in steps()) {
        run::<2>(&steps)?;
    }

    #[test]
    fn a_ring_of_a_hundred_and_twenty_eight_behaves_as_a_queue_of_a_hundred_and_twenty_seven(steps in steps()) {
        run::<128>(&steps)?;
    }
}
