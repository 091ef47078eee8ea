use super::*;
use crate::network::random_block_network;

fn opts() -> CostOptions {
    CostOptions::default()
}

fn example_1() -> Network {
    // The paper's Example 1: P = G Gᵀ = [[5, −3], [−3, 4]], G = chol(P).
    let p = DMatrix::from_row_slice(2, 2, &[5.0, -3.0, -3.0, 4.0]);
    let g = p.cholesky().unwrap().l();
    Network::new(
        DMatrix::from_row_slice(2, 2, &[-1.0, 0.0, 0.0, -2.0]),
        g,
        vec![DMatrix::from_column_slice(2, 1, &[1.0, 1.0])],
    )
    .unwrap()
}

#[test]
fn example_1_reproduces_the_paper() {
    let net = example_1();
    let ev = Evaluation::new(&net, &[1.0], &opts()).unwrap();
    let expected = DMatrix::from_row_slice(2, 2, &[2.0, -1.0, -1.0, 1.0]);
    assert!((ev.sigma() - &expected).norm() < 1e-13, "{}", ev.sigma());
    assert!((ev.value() - 3.0).abs() < 1e-13);
    let sc = ev.sigma() * DMatrix::from_column_slice(2, 1, &[1.0, 1.0]);
    assert!((sc[0] - 1.0).abs() < 1e-13 && sc[1].abs() < 1e-13);
}

#[test]
fn scalar_closed_form_derivatives() {
    // 2aσ − r c² σ² + g² = 0 ⇒ σ = (a + √(a² + r c² g²)) / (r c²).
    let (a, c, g) = (0.7, 1.3, 0.9);
    let net = Network::new(
        DMatrix::from_element(1, 1, a),
        DMatrix::from_element(1, 1, g),
        vec![DMatrix::from_element(1, 1, c)],
    )
    .unwrap();
    let r = 2.5;
    let k = c * c;
    let d = (a * a + r * k * g * g).sqrt();
    let sigma = (a + d) / (r * k);
    // dσ/dr from implicit differentiation: −kσ² / (2(a − rkσ)) = kσ² / (2d).
    let d1 = -k * sigma * sigma / (2.0 * d);
    // d²σ/dr² = −k(2σσ' d − σ² d') / (2d²) with d' = k g² / (2d).
    let dd = k * g * g / (2.0 * d);
    let d2 = -k * (2.0 * sigma * d1 * d - sigma * sigma * dd) / (2.0 * d * d);
    let (v, grad, h) = value_gradient_hessian(&net, &[r], &opts(), Threads::Sequential).unwrap();
    assert!((v - sigma).abs() < 1e-14 * sigma);
    assert!(
        (grad[0] - d1).abs() < 1e-13 * d1.abs(),
        "{} vs {d1}",
        grad[0]
    );
    assert!(
        (h[(0, 0)] - d2).abs() < 1e-12 * d2.abs(),
        "{} vs {d2}",
        h[(0, 0)]
    );
    let hv = hvp(&net, &[r], &[vec![2.0]], &opts()).unwrap();
    assert!((hv[0][0] - 2.0 * d2).abs() < 1e-12 * d2.abs());
}

fn rates(nn: usize) -> Vec<f64> {
    (0..nn).map(|i| 0.5 + 0.37 * ((i * 7) % 5) as f64).collect()
}

/// The gradient at `r` against central differences of the cost (step `1e-5·r_i`), and negative.
fn assert_gradient_matches_central_differences(net: &Network, r: &[f64]) {
    let (_, grad) = value_gradient(net, r, &opts()).unwrap();
    for i in 0..r.len() {
        let h = 1e-5 * r[i];
        let mut rp = r.to_vec();
        let mut rm = r.to_vec();
        rp[i] += h;
        rm[i] -= h;
        let fd = (cost(net, &rp, &opts()).unwrap() - cost(net, &rm, &opts()).unwrap()) / (2.0 * h);
        assert!(
            (fd - grad[i]).abs() <= 1e-7 * grad[i].abs(),
            "i={i}: {fd} vs {}",
            grad[i]
        );
        assert!(grad[i] < 0.0);
    }
}

#[test]
fn gradient_matches_central_differences() {
    let net = random_block_network(3, &[2, 3, 1, 2], &[1, 2, 1, 1], 0.3);
    assert_gradient_matches_central_differences(&net, &rates(4));
}

/// The Hessian at `r` against central differences of the gradient (step `1e-5·r_j`).
fn assert_hessian_matches_differences_of_the_gradient(
    net: &Network,
    r: &[f64],
    hess: &DMatrix<f64>,
) {
    for j in 0..r.len() {
        let h = 1e-5 * r[j];
        let mut rp = r.to_vec();
        let mut rm = r.to_vec();
        rp[j] += h;
        rm[j] -= h;
        let gp = value_gradient(net, &rp, &opts()).unwrap().1;
        let gm = value_gradient(net, &rm, &opts()).unwrap().1;
        for i in 0..r.len() {
            let fd = (gp[i] - gm[i]) / (2.0 * h);
            assert!(
                (fd - hess[(i, j)]).abs() <= 1e-6 * hess.norm(),
                "({i},{j}): {fd} vs {}",
                hess[(i, j)]
            );
        }
    }
}

#[test]
fn hessian_matches_differences_of_the_gradient_and_hvp() {
    let net = random_block_network(4, &[3, 2, 2], &[1, 1, 2], 0.4);
    let r = rates(3);
    let (_, _, hess) = value_gradient_hessian(&net, &r, &opts(), Threads::Sequential).unwrap();
    let (_, _, hess_par) = value_gradient_hessian(&net, &r, &opts(), Threads::All).unwrap();
    assert_eq!(hess, hess_par);
    assert_hessian_matches_differences_of_the_gradient(&net, &r, &hess);
    assert!(hess.symmetric_eigenvalues().min() >= -1e-12 * hess.norm());
    let vs = vec![vec![1.0, -2.0, 0.5], vec![0.0, 1.0, 0.0]];
    let hv = hvp(&net, &r, &vs, &opts()).unwrap();
    for (v, hv) in vs.iter().zip(&hv) {
        let exact = &hess * DMatrix::from_column_slice(3, 1, v);
        for i in 0..3 {
            assert!((exact[i] - hv[i]).abs() <= 1e-12 * hess.norm());
        }
    }
}

#[test]
fn hessian_block_is_the_principal_block_of_the_hessian() {
    // The block on J from |J| solves against the full Hessian's entries (formed from all N),
    // whatever the order of J; out-of-range indices are input errors.
    let net = random_block_network(7, &[2, 3, 2, 2], &[1, 2, 1, 1], 0.3);
    let r = vec![0.7, 1.3, 2.1, 0.4];
    let point = CostPoint::at(Arc::new(net), &r, &opts()).unwrap();
    let full = point.hessian(Threads::Sequential).unwrap();
    for idx in [vec![0, 2], vec![3, 1, 2], vec![1], vec![0, 1, 2, 3]] {
        let block = point.hessian_block(&idx, Threads::All).unwrap();
        for (a, &i) in idx.iter().enumerate() {
            for (b, &j) in idx.iter().enumerate() {
                let scale = full[(i, i)].abs().max(full[(j, j)].abs());
                assert!(
                    (block[(a, b)] - full[(i, j)]).abs() <= 1e-13 * scale,
                    "{idx:?}"
                );
            }
        }
    }
    assert_eq!(
        point.hessian_block(&[], Threads::All).unwrap().shape(),
        (0, 0)
    );
    assert!(matches!(
        point.hessian_block(&[4], Threads::All),
        Err(Error::InvalidInput(_))
    ));
}

#[test]
fn decoupled_network_separates() {
    let sizes = [2, 3, 2];
    let net = random_block_network(5, &sizes, &[1, 1, 1], 0.0);
    let r = rates(3);
    let (v, grad, hess) = value_gradient_hessian(&net, &r, &opts(), Threads::Sequential).unwrap();
    let mut lo = 0;
    let mut total = 0.0;
    for (i, &ni) in sizes.iter().enumerate() {
        let sub = Network::new(
            net.a().view((lo, lo), (ni, ni)).into_owned(),
            net.g().view((lo, lo), (ni, ni)).into_owned(),
            vec![net.sensors()[i].matrix().rows(lo, ni).into_owned()],
        )
        .unwrap();
        let (vi, gi, hi) =
            value_gradient_hessian(&sub, &[r[i]], &opts(), Threads::Sequential).unwrap();
        total += vi;
        assert!((gi[0] - grad[i]).abs() <= 1e-11 * grad[i].abs());
        assert!((hi[(0, 0)] - hess[(i, i)]).abs() <= 1e-10 * hess[(i, i)].abs());
        lo += ni;
    }
    assert!((total - v).abs() <= 1e-12 * v);
    for i in 0..3 {
        for j in 0..3 {
            if i != j {
                assert!(hess[(i, j)].abs() <= 1e-10 * hess.norm());
            }
        }
    }
}

#[test]
fn batches_are_bitwise_identical_to_single_calls() {
    let net = random_block_network(6, &[2; 6], &[1; 6], 0.2);
    let rows: Vec<Vec<f64>> = (0..9)
        .map(|k| {
            (0..6)
                .map(|i| 0.3 + 0.1 * ((k + 2 * i) % 7) as f64)
                .collect()
        })
        .collect();
    let costs = cost_many(&net, &rows, &opts(), Threads::All).unwrap();
    let grads = value_gradient_many(&net, &rows, &opts(), Threads::All).unwrap();
    let costs3 = cost_many(&net, &rows, &opts(), Threads::Count(3)).unwrap();
    let grads1 = value_gradient_many(&net, &rows, &opts(), Threads::Sequential).unwrap();
    assert!(cost_many(&net, &rows, &opts(), Threads::Count(0)).is_err());
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(costs[k].as_ref().unwrap(), &cost(&net, r, &opts()).unwrap());
        assert_eq!(costs3[k].as_ref().unwrap(), costs[k].as_ref().unwrap());
        assert_eq!(grads1[k].as_ref().unwrap(), grads[k].as_ref().unwrap());
        assert_eq!(
            grads[k].as_ref().unwrap(),
            &value_gradient(&net, r, &opts()).unwrap()
        );
    }
}

#[test]
fn parallel_hessian_is_bitwise_identical() {
    let net = random_block_network(8, &[2, 3, 2, 2, 1, 2], &[1, 1, 2, 1, 1, 1], 0.3);
    let r = rates(6);
    let seq = value_gradient_hessian(&net, &r, &opts(), Threads::Sequential).unwrap();
    for t in [Threads::All, Threads::Count(3), Threads::Count(1)] {
        assert_eq!(value_gradient_hessian(&net, &r, &opts(), t).unwrap(), seq);
    }
    assert!(value_gradient_hessian(&net, &r, &opts(), Threads::Count(0)).is_err());
}

#[test]
fn owned_point_matches_the_borrowing_api_bitwise() {
    let net = random_block_network(11, &[2, 3, 2, 1, 2], &[1, 1, 2, 1, 1], 0.3);
    let r = rates(5);
    let shared = Arc::new(net.clone());
    let point = CostPoint::at(Arc::clone(&shared), &r, &opts()).unwrap();
    // The point owns its share: dropping every other handle leaves it usable.
    drop(shared);
    let ev = Evaluation::new(&net, &r, &opts()).unwrap();
    let adj = ev.adjoint().unwrap();
    assert_eq!(point.evaluation().value(), ev.value());
    assert_eq!(point.evaluation().sigma(), ev.sigma());
    assert_eq!(point.evaluation().rates(), &r[..]);
    assert_eq!(point.gradient(), adj.gradient());
    assert_eq!(point.y(), adj.y());
    let h = point.hessian(Threads::Sequential).unwrap();
    assert_eq!(h, adj.hessian(Threads::Sequential).unwrap());
    let vs = vec![
        vec![1.0, -2.0, 0.5, 0.0, 3.0],
        vec![0.0, 1.0, 0.0, 0.0, 0.0],
        vec![0.2, 0.2, -0.1, -0.3, 0.0],
    ];
    let hv = point.hvp(&vs).unwrap();
    // Repeated products on one point: deterministic, and the same as a fresh evaluation.
    assert_eq!(hv, point.hvp(&vs).unwrap());
    assert_eq!(hv, hvp(&net, &r, &vs, &opts()).unwrap());
    for (v, hv) in vs.iter().zip(&hv) {
        let exact = &h * DMatrix::from_column_slice(5, 1, v);
        for i in 0..5 {
            assert!((exact[i] - hv[i]).abs() <= 1e-12 * h.norm(), "{i}");
        }
    }
    // into_adjoint on a borrowing evaluation gives the same numbers.
    let owned = Evaluation::new(&net, &r, &opts())
        .unwrap()
        .into_adjoint()
        .unwrap();
    assert_eq!(owned.hvp(&vs).unwrap(), hv);
    assert_eq!(
        owned.sigma_derivative(2).unwrap(),
        adj.sigma_derivative(2).unwrap()
    );
}

#[test]
fn owned_point_hvp_matches_differences_of_the_gradient() {
    let net = Arc::new(random_block_network(12, &[2, 2, 3], &[1, 2, 1], 0.5));
    let r = rates(3);
    let point = CostPoint::at(Arc::clone(&net), &r, &opts()).unwrap();
    let v = [0.7, -0.4, 1.1];
    let hv = &point.hvp(&[v.to_vec()]).unwrap()[0];
    let h = 1e-5;
    let shift = |s: f64| -> Vec<f64> { r.iter().zip(&v).map(|(a, b)| a + s * b).collect() };
    let gp = CostPoint::at(Arc::clone(&net), &shift(h), &opts()).unwrap();
    let gm = CostPoint::at(Arc::clone(&net), &shift(-h), &opts()).unwrap();
    let scale = hv.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    for i in 0..3 {
        let fd = (gp.gradient()[i] - gm.gradient()[i]) / (2.0 * h);
        assert!((fd - hv[i]).abs() <= 1e-6 * scale, "{i}: {fd} vs {}", hv[i]);
    }
}

#[test]
fn owned_point_is_send_and_sync_and_usable_across_threads() {
    fn assert_send_sync<T: Send + Sync + 'static>() {}
    assert_send_sync::<CostPoint>();
    let net = Arc::new(random_block_network(13, &[2; 4], &[1; 4], 0.2));
    let point = Arc::new(CostPoint::at(net, &rates(4), &opts()).unwrap());
    let v = vec![vec![1.0, 0.0, -1.0, 0.5]];
    let here = point.hvp(&v).unwrap();
    let handles: Vec<_> = (0..2)
        .map(|_| {
            let (p, v) = (Arc::clone(&point), v.clone());
            std::thread::spawn(move || p.hvp(&v).unwrap())
        })
        .collect();
    for h in handles {
        assert_eq!(h.join().unwrap(), here);
    }
}

#[test]
fn owned_point_refuses_bad_input() {
    let net = Arc::new(example_1());
    assert!(matches!(
        CostPoint::at(Arc::clone(&net), &[1.0, 2.0], &opts()),
        Err(Error::Shape(_))
    ));
    assert!(matches!(
        CostPoint::at(Arc::clone(&net), &[-1.0], &opts()),
        Err(Error::InvalidInput(_))
    ));
    // A rate 0 is a valid rate (a sensor switched off); with every sensor off W = 0 and Σ is the
    // open loop's covariance, AΣ + ΣAᵀ + GGᵀ = 0: here Σ_ij = P_ij / −(a_i + a_j).
    let off = Evaluation::new(&net, &[0.0], &opts()).unwrap();
    let expected = DMatrix::from_row_slice(2, 2, &[2.5, -1.0, -1.0, 1.0]);
    assert!((off.sigma() - &expected).norm() < 1e-14, "{}", off.sigma());
    assert!(CostPoint::at(Arc::clone(&net), &[0.0], &opts()).is_ok());
    let point = CostPoint::at(net, &[1.0], &opts()).unwrap();
    assert!(matches!(point.hvp(&[vec![1.0, 2.0]]), Err(Error::Shape(_))));
    assert!(matches!(
        point.hvp(&[vec![f64::INFINITY]]),
        Err(Error::NonFinite(_))
    ));
    assert!(matches!(
        point.sigma_derivative(1),
        Err(Error::InvalidInput(_))
    ));
    assert!(point.hvp(&[]).unwrap().is_empty());
}

#[test]
fn bad_rates_are_refused() {
    let net = example_1();
    assert!(matches!(
        cost(&net, &[1.0, 1.0], &opts()),
        Err(Error::Shape(_))
    ));
    assert!(matches!(
        cost(&net, &[-1.0], &opts()),
        Err(Error::InvalidInput(_))
    ));
    assert!(matches!(
        cost(&net, &[f64::NAN], &opts()),
        Err(Error::NonFinite(_))
    ));
    let ev = Evaluation::new(&net, &[1.0], &opts()).unwrap();
    assert!(ev.weight()[(0, 1)] == 1.0);
}

#[test]
fn undetectable_networks_fail_with_the_care_error() {
    // An unstable mode that no sensor sees.
    let net = Network::new(
        DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]),
        DMatrix::identity(2, 2),
        vec![DMatrix::from_column_slice(2, 1, &[0.0, 1.0])],
    )
    .unwrap();
    let err = cost(&net, &[1.0], &opts()).unwrap_err();
    assert!(
        matches!(
            err,
            Error::NoStabilizingSolution(_) | Error::SingularProblem(_)
        ),
        "{err:?}"
    );
}

/// A network with an error weight `M = LᵀL + 0.1 I` (`n × n`, deterministic).
fn weighted(net: Network) -> Network {
    let n = net.order();
    let l = DMatrix::from_fn(n, n, |i, j| ((i * 3 + j * 5) % 7) as f64 / 7.0 - 0.4);
    let m = l.transpose() * &l + DMatrix::<f64>::identity(n, n) * 0.1;
    net.with_error_weight(m).unwrap()
}

#[test]
fn weighted_error_value_gradient_and_hessian() {
    let plain = random_block_network(3, &[2, 3, 1, 2], &[1, 2, 1, 1], 0.3);
    let net = weighted(plain.clone());
    let m = net.error_weight().unwrap().clone();
    let r = rates(4);
    let point = Evaluation::new(&net, &r, &opts()).unwrap();
    let sigma = Evaluation::new(&plain, &r, &opts())
        .unwrap()
        .sigma()
        .clone();
    assert_eq!(point.sigma(), &sigma);
    let want = (&m * &sigma).trace();
    assert!((point.value() - want).abs() <= 1e-14 * want);
    // the bound scales with ‖M‖₂ and still covers rounding
    assert!(point.value_error() >= 1e-16 * want);
    assert_gradient_matches_central_differences(&net, &r);
    let (_, _, hess) = value_gradient_hessian(&net, &r, &opts(), Threads::Sequential).unwrap();
    assert_hessian_matches_differences_of_the_gradient(&net, &r, &hess);
}

#[test]
fn error_weight_is_validated() {
    let net = random_block_network(3, &[2, 1], &[1, 1], 0.3);
    let bad = [
        DMatrix::<f64>::identity(2, 2),
        DMatrix::from_row_slice(3, 3, &[1.0, 2.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
        -DMatrix::<f64>::identity(3, 3),
        DMatrix::<f64>::zeros(3, 3),
        DMatrix::from_element(3, 3, f64::NAN),
    ];
    for m in bad {
        assert!(net.clone().with_error_weight(m).is_err());
    }
    // positive semidefinite and singular is fine
    let m = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![1.0, 0.0, 0.0]));
    assert!(net.with_error_weight(m).is_ok());
}

#[test]
fn schur_coordinate_hvp_matches_the_congruence_route() {
    // Products in Schur coordinates vs two full Lyapunov solves in the original basis, for sensors
    // with one and two outputs, with and without an error weight, on cold and warm points.
    let plain = random_block_network(3, &[2, 3, 1, 2], &[1, 2, 1, 1], 0.3);
    let r = rates(4);
    let vs = [vec![1.0, -2.0, 0.5, 0.25], vec![0.0, 1.0, 0.0, 0.0]];
    for net in [plain.clone(), weighted(plain)] {
        let eval = Evaluation::new(&net, &r, &opts()).unwrap();
        let adj = eval.adjoint().unwrap();
        let mut r2 = r.clone();
        r2[1] *= 1.01;
        let warm = adj.warm_evaluation(&r2, &opts()).unwrap();
        assert!(warm.warm_info().is_some_and(|w| w.fallback.is_none()));
        let warm_adj = warm.adjoint().unwrap();
        for a in [&adj, &warm_adj] {
            for v in &vs {
                let fast = a.hvp(std::slice::from_ref(v)).unwrap().remove(0);
                let slow = a.hvp_congruence(v).unwrap();
                let scale = slow.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
                for (f, s) in fast.iter().zip(&slow) {
                    assert!((f - s).abs() <= 1e-12 * scale, "{f} vs {s}");
                }
            }
        }
    }
}
