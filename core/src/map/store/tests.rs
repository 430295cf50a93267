use super::*;
use crate::testing::on_big_stack;

fn feats(n: usize) -> std::vec::Vec<Feature> {
    (0..n)
        .map(|i| Feature {
            x: i as f32,
            y: 0.0,
            level: 0,
            angle: 0.0,
            desc: [i as u8; 32],
            ur: -1.0,
            depth_m: 0.0,
            class: crate::seg::VOID,
        })
        .collect()
}

fn new_map() -> std::boxed::Box<Map> {
    let mut m = std::boxed::Box::new(Map::new());
    m.clear();
    m
}

fn lm(m: &mut Map) -> u32 {
    m.new_landmark(Vector3::new(0.0, 0.0, 5.0), [0; 32], 0, 5.0).unwrap()
}

/// Covisibility weights counted the slow way, from the keyframes' landmark tables.
fn covis_by_scan(m: &Map, a: u8, b: u8) -> u16 {
    let (ka, kb) = (m.kf(a), m.kf(b));
    let n = ka.landmark[..ka.features.len()]
        .iter()
        .filter(|&&l| l != NO_LANDMARK && kb.landmark[..kb.features.len()].contains(&l))
        .count();
    n as u16
}

#[test]
fn covisibility_stays_exact_through_adds_removals_and_merges() {
    on_big_stack(|| {
        let mut m = new_map();
        let f = feats(8);
        let a = m.push_keyframe(0, Se3::identity(), &f, 0).unwrap();
        let b = m.push_keyframe(1, Se3::identity(), &f, 1).unwrap();
        let c = m.push_keyframe(2, Se3::identity(), &f, 2).unwrap();
        let ids: std::vec::Vec<u32> = (0..6).map(|_| lm(&mut m)).collect();
        for (i, &id) in ids.iter().enumerate() {
            m.add_observation(a, i, id);
            if i % 2 == 0 {
                m.add_observation(b, i, id);
            }
            if i < 3 {
                m.add_observation(c, i + 4, id);
            }
        }
        let check = |m: &Map| {
            for (x, y) in [(a, b), (a, c), (b, c)] {
                assert_eq!(m.covisibility(x, y), covis_by_scan(m, x, y), "{x}-{y}");
                assert_eq!(m.covisibility(x, y), m.covisibility(y, x));
            }
        };
        assert_eq!(m.covisibility(a, b), 3);
        assert_eq!(m.covisibility(a, c), 3);
        check(&m);
        m.remove_observation(a, 0);
        check(&m);
        // Merge: observations of ids[5] (only in a) move onto ids[1] where a has none... a
        // already observes ids[1], so that observation is dropped instead.
        m.merge_landmark(ids[5], ids[1]);
        assert!(!m.lm(ids[5]).alive);
        check(&m);
        m.remove_keyframe(b);
        assert_eq!(m.covisibility(a, b), 0);
        check(&m);
        assert_eq!(m.counters.landmarks_fused, 1);
    });
}

#[test]
fn landmarks_die_with_their_last_observation() {
    on_big_stack(|| {
        let mut m = new_map();
        let f = feats(4);
        let a = m.push_keyframe(0, Se3::identity(), &f, 0).unwrap();
        let l0 = lm(&mut m);
        let l1 = lm(&mut m);
        m.add_observation(a, 0, l0);
        m.add_observation(a, 1, l1);
        let b = m.push_keyframe(1, Se3::identity(), &f, 1).unwrap();
        m.add_observation(b, 2, l1);
        assert_eq!(m.landmark_count(), 2);
        m.remove_keyframe(a);
        assert_eq!(m.len(), 1);
        assert!(!m.lm(l0).alive, "only the removed keyframe saw l0");
        assert!(m.lm(l1).alive);
        assert_eq!(m.lm(l1).observations(), &[Obs { kf: b, feat: 2 }]);
        assert_eq!(m.landmark_count(), 1);
    });
}

#[test]
fn a_full_store_evicts_the_least_recently_used_keyframe() {
    on_big_stack(|| {
        let mut m = new_map();
        let f = feats(2);
        for i in 0..MAX_KEYFRAMES as u32 {
            m.push_keyframe(i, Se3::identity(), &f, i).unwrap();
        }
        // Keyframe 0 was used recently, so keyframe 1 is the least recently used.
        let s0 = m.keyframe_slots()[0];
        m.kf_mut(s0).last_used = 1000;
        let s = m.push_keyframe(999, Se3::identity(), &f, 1001).unwrap();
        assert_eq!(m.len(), MAX_KEYFRAMES);
        assert_eq!(m.counters.keyframe_evictions, 1);
        assert!(m.kf(s0).alive);
        assert_eq!(m.kf(s).frame_index, 999);
        assert!(m.keyframe_slots().iter().all(|&k| m.kf(k).frame_index != 1));
        // Nothing evictable when every keyframe is in use now.
        for &k in m.keyframe_slots().to_vec().iter() {
            m.kf_mut(k).last_used = 5000;
        }
        assert_eq!(m.push_keyframe(1000, Se3::identity(), &f, 5000), None);
    });
}

#[test]
fn a_full_observation_list_drops_the_oldest_keyframe() {
    on_big_stack(|| {
        let mut m = new_map();
        let f = feats(1);
        let id = lm(&mut m);
        let mut slots = std::vec::Vec::new();
        for i in 0..=MAX_OBS as u32 {
            let s = m.push_keyframe(i, Se3::identity(), &f, i).unwrap();
            m.add_observation(s, 0, id);
            slots.push(s);
        }
        assert_eq!(usize::from(m.lm(id).n_obs), MAX_OBS);
        assert_eq!(m.counters.observation_overflow, 1);
        assert_eq!(m.lm(id).feature_in(slots[0]), None);
        assert_eq!(m.kf(slots[0]).landmark[0], NO_LANDMARK);
        assert_eq!(m.covisibility(slots[0], slots[1]), 0);
        assert_eq!(m.covisibility(slots[1], slots[MAX_OBS]), 1);
    });
}

#[test]
fn landmark_store_overflow_is_counted() {
    on_big_stack(|| {
        let mut m = new_map();
        for _ in 0..MAX_LANDMARKS {
            assert!(m.new_landmark(Vector3::zeros(), [0; 32], 0, 1.0).is_some());
        }
        assert!(m.new_landmark(Vector3::zeros(), [0; 32], 0, 1.0).is_none());
        assert_eq!(m.counters.landmark_overflow, 1);
        m.remove_landmark(5);
        assert_eq!(m.new_landmark(Vector3::zeros(), [0; 32], 0, 1.0), Some(5));
    });
}

#[test]
fn best_covisible_orders_by_shared_landmarks() {
    on_big_stack(|| {
        let mut m = new_map();
        let f = feats(10);
        let a = m.push_keyframe(0, Se3::identity(), &f, 0).unwrap();
        let b = m.push_keyframe(1, Se3::identity(), &f, 0).unwrap();
        let c = m.push_keyframe(2, Se3::identity(), &f, 0).unwrap();
        for i in 0..5 {
            let id = lm(&mut m);
            m.add_observation(a, i, id);
            m.add_observation(c, i, id);
            if i < 2 {
                m.add_observation(b, i, id);
            }
        }
        let stamp = m.next_stamp();
        let mut out: heapless::Vec<u8, 8> = heapless::Vec::new();
        assert_eq!(m.best_covisible(a, 5, 1, stamp, &mut out), 2);
        assert_eq!(&out[..], &[c, b]);
        // Stamped keyframes are not listed twice.
        assert_eq!(m.best_covisible(a, 5, 1, stamp, &mut out), 0);
    });
}

#[test]
fn landmark_class_is_the_most_frequent_with_ties_to_the_lowest_id() {
    let mut l = Landmark::EMPTY;
    assert_eq!(l.class(), None);
    l.class_hist[8] = 2;
    l.class_hist[3] = 1;
    assert_eq!(l.class(), Some(8));
    l.class_hist[4] = 2;
    assert_eq!(l.class(), Some(4));
}
