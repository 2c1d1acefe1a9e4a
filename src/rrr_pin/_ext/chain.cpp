// The compiled closed-chain engine (chain.hpp): kinematics of the loop closure, exact KKT
// dynamics, the projection, the reduced-model FL law and the sampled rollout, each in the order
// of the Python engine (rrr_pin.sim.closed_chain, rrr_pin.model.closed_chain,
// rrr_pin.control.closed_chain).
#include "chain.hpp"

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>

namespace rrr_pin
{
  namespace
  {
    /// max |v_i|, NaN if any entry is NaN (as numpy's max of abs).
    double maxabs(const Vec & v)
    {
      double m = 0.0;
      for (Eigen::Index i = 0; i < v.size(); ++i)
      {
        const double a = std::abs(v[i]);
        if (std::isnan(a))
          return a;
        m = a > m ? a : m;
      }
      return m;
    }

    const double kInf = std::numeric_limits<double>::infinity();
  } // namespace

  ChainModel::ChainModel(const std::string & serialized, const IVec & joint_a_,
                         const IVec & joint_b_, const Mat & anchor_a_, const Mat & anchor_b_,
                         const IVec & rows_, const IVec & act_, const IVec & pas_,
                         const Vec & home_)
  : tree(serialized)
  , joint_a(joint_a_)
  , joint_b(joint_b_)
  , anchor_a(anchor_a_)
  , anchor_b(anchor_b_)
  , rows(rows_)
  , act(act_)
  , pas(pas_)
  , home(home_)
  {
    const Model & m = tree.model;
    const Eigen::Index nc = joint_a.size();
    if (m.nq != m.nv)
      throw std::invalid_argument("closed chain: nq != nv (hinge and slide joints only)");
    if (joint_b.size() != nc || anchor_a.rows() != 3 || anchor_b.rows() != 3
        || anchor_a.cols() != nc || anchor_b.cols() != nc)
      throw std::invalid_argument("closed chain: anchors must be 3 x nc with nc joints per side");
    for (Eigen::Index k = 0; k < nc; ++k)
      if (joint_a[k] < 0 || joint_a[k] >= m.njoints || joint_b[k] < 0 || joint_b[k] >= m.njoints)
        throw std::invalid_argument("closed chain: anchor joint index out of range");
    if (act.size() + pas.size() != m.nv || rows.size() != pas.size() || home.size() != m.nq)
      throw std::invalid_argument("closed chain: act, pas, rows or home of the wrong size");
    for (Eigen::Index i = 0; i < rows.size(); ++i)
      if (rows[i] < 0 || rows[i] >= 3 * nc)
        throw std::invalid_argument("closed chain: row index out of range");
    for (Eigen::Index i = 0; i < act.size(); ++i)
      if (act[i] < 0 || act[i] >= m.nv)
        throw std::invalid_argument("closed chain: actuated index out of range");
    for (Eigen::Index i = 0; i < pas.size(); ++i)
      if (pas[i] < 0 || pas[i] >= m.nv)
        throw std::invalid_argument("closed chain: passive index out of range");
  }

  ChainWork::ChainWork(const ChainModel & cm_)
  : cm(cm_)
  , data(cm_.tree.model)
  {
    const Eigen::Index nv = cm.nv(), np = cm.pas.size(), nc = cm.joint_a.size();
    J.resize(np, nv);
    Jfull.resize(3 * nc, nv);
    Jj.setZero(6, nv);
    Jp.resize(np, np);
    Ja.resize(np, cm.act.size());
    phi.resize(np);
    gap.resize(3 * nc);
    g.resize(np);
    qdd.resize(nv);
    zero.setZero(nv);
  }

  void ChainWork::point(int joint, const Eigen::Ref<const Eigen::Vector3d> & t,
                        Eigen::Vector3d & p) const
  {
    const pinocchio::SE3 & oMi = data.oMi[static_cast<std::size_t>(joint)];
    p.noalias() = oMi.rotation() * t;
    p += oMi.translation();
  }

  void ChainWork::jacobian(const Vec & q)
  {
    pinocchio::computeJointJacobians(cm.tree.model, data, CRef(q));
    points();
  }

  void ChainWork::points()
  {
    const Model & model = cm.tree.model;
    const Eigen::Index nc = cm.joint_a.size();
    Eigen::Vector3d pa, pb;
    for (Eigen::Index k = 0; k < nc; ++k)
    {
      auto block = Jfull.middleRows<3>(3 * k);
      block.setZero();
      for (int side = 0; side < 2; ++side)
      {
        const int j = side ? cm.joint_b[k] : cm.joint_a[k];
        Eigen::Vector3d & p = side ? pb : pa;
        point(j, side ? cm.anchor_b.col(k) : cm.anchor_a.col(k), p);
        if (j == 0)
          continue;  // the ground: no velocity
        Jj.setZero();
        pinocchio::getJointJacobian(model, data, static_cast<pinocchio::JointIndex>(j),
                                    pinocchio::WORLD, Jj);
        // Linear velocity of the point p of the body: v_O + w x p (WORLD spatial columns).
        const double sgn = side ? -1.0 : 1.0;
        for (Eigen::Index c = 0; c < Jj.cols(); ++c)
        {
          const Eigen::Vector3d w = Jj.col(c).tail<3>();
          block.col(c) += sgn * (Jj.col(c).head<3>() + w.cross(p));
        }
      }
      gap.segment<3>(3 * k) = pa - pb;
    }
    for (Eigen::Index i = 0; i < cm.rows.size(); ++i)
    {
      J.row(i) = Jfull.row(cm.rows[i]);
      phi[i] = gap[cm.rows[i]];
    }
    for (Eigen::Index i = 0; i < cm.pas.size(); ++i)
      Jp.col(i) = J.col(cm.pas[i]);
    for (Eigen::Index i = 0; i < cm.act.size(); ++i)
      Ja.col(i) = J.col(cm.act[i]);
  }

  void ChainWork::residual(const Vec & q)
  {
    pinocchio::forwardKinematics(cm.tree.model, data, CRef(q));
    const Eigen::Index nc = cm.joint_a.size();
    Eigen::Vector3d pa, pb;
    for (Eigen::Index k = 0; k < nc; ++k)
    {
      point(cm.joint_a[k], cm.anchor_a.col(k), pa);
      point(cm.joint_b[k], cm.anchor_b.col(k), pb);
      gap.segment<3>(3 * k) = pa - pb;
    }
    for (Eigen::Index i = 0; i < cm.rows.size(); ++i)
      phi[i] = gap[cm.rows[i]];
  }

  void ChainWork::gamma(const Vec & q, const Vec & qd)
  {
    const Model & model = cm.tree.model;
    pinocchio::forwardKinematics(model, data, CRef(q), CRef(qd), CRef(zero));
    gamma_points();
  }

  void ChainWork::gamma_points()
  {
    const Eigen::Index nc = cm.joint_a.size();
    Eigen::Vector3d acc[2];
    for (Eigen::Index k = 0; k < nc; ++k)
    {
      for (int side = 0; side < 2; ++side)
      {
        const auto j = static_cast<std::size_t>(side ? cm.joint_b[k] : cm.joint_a[k]);
        const Eigen::Vector3d t = side ? cm.anchor_b.col(k) : cm.anchor_a.col(k);
        // Classical acceleration of the point t of joint j's body (local frame), in world axes.
        const pinocchio::Motion & v = data.v[j];
        const pinocchio::Motion & a = data.a[j];
        const Eigen::Vector3d vp = v.linear() + v.angular().cross(t);
        const Eigen::Vector3d ap = a.linear() + a.angular().cross(t) + v.angular().cross(vp);
        acc[side].noalias() = data.oMi[j].rotation() * ap;
      }
      gap.segment<3>(3 * k) = acc[0] - acc[1];
    }
    for (Eigen::Index i = 0; i < cm.rows.size(); ++i)
      g[i] = gap[cm.rows[i]];
  }

  double ChainWork::cond() const
  {
    if (Jp.size() == 0)
      return 1.0;
    Eigen::JacobiSVD<Mat> svd(Jp);
    const Vec & s = svd.singularValues();
    const double lo = s.minCoeff();
    return lo > 0.0 ? s.maxCoeff() / lo : kInf;
  }

  int ChainWork::close(Vec & q, double tol, int max_iter, double cond_limit, double & cond_out,
                       bool fresh)
  {
    for (int it = 0; it < max_iter; ++it)
    {
      if (it || !fresh)
        jacobian(q);
      if (maxabs(phi) <= tol)
      {
        cond_out = cond();
        return cond_out <= cond_limit ? 0 : 1;
      }
      f = Jp.partialPivLu().solve(phi);
      if (!f.allFinite())
      {
        cond_out = kInf;
        return 1;
      }
      for (Eigen::Index i = 0; i < cm.pas.size(); ++i)
        q[cm.pas[i]] -= f[i];
    }
    return 2;
  }

  void ChainWork::S_of(Mat & Sout)
  {
    Sout.setZero(cm.nv(), cm.na());
    const Mat X = Jp.partialPivLu().solve(Ja);
    for (Eigen::Index i = 0; i < cm.act.size(); ++i)
      Sout(cm.act[i], i) = 1.0;
    for (Eigen::Index i = 0; i < cm.pas.size(); ++i)
      Sout.row(cm.pas[i]) = -X.row(i);
  }


  const Vec & ChainWork::acceleration(const Vec & q, const Vec & qd, const Vec & u)
  {
    // M qdd = u - nle + J^T f with J qdd + gamma = 0, f eliminated by the Schur complement
    // J M^-1 J^T (the solution constraintDynamics converges to; J has independent rows).
    // The forward pass of nonLinearEffects serves the kinematics too: its local placements
    // give the world placements (hence the joint Jacobians and J), its velocities and its
    // accelerations with gravity a_gf = a + oMi^-1 (-g) give the zero-qdd accelerations a
    // (hence gamma); then CRBA.
    const Model & model = cm.tree.model;
    b = u - pinocchio::nonLinearEffects(model, data, CRef(q), CRef(qd));
    for (pinocchio::JointIndex i = 1; i < static_cast<pinocchio::JointIndex>(model.njoints); ++i)
    {
      data.oMi[i] = data.oMi[model.parents[i]] * data.liMi[i];
      data.a[i] = data.a_gf[i] + data.oMi[i].actInv(model.gravity);
    }
    gamma_points();
    pinocchio::computeJointJacobians(model, data);
    points();
    M = pinocchio::crba(model, data, CRef(q));
    M.triangularView<Eigen::StrictlyLower>() = M.transpose();
    llt_M.compute(M);
    MiJt = llt_M.solve(J.transpose());
    qdd = llt_M.solve(b);
    A.noalias() = J * MiJt;
    f.noalias() = J * qdd;
    f += g;
    llt_A.compute(A);
    f = llt_A.solve(f);
    qdd.noalias() -= MiJt * f;
    return qdd;
  }

  namespace
  {
    /// ChainFLLaw evaluated on the law's closed chain (ClosedChain.reduced + ReducedTracking).
    class ChainFLEval
    {
    public:
      ChainFLEval(const ChainFLLaw & law, const ChainModel & nominal, const ChainInputs & in)
      : p(law)
      , w(nominal)
      , in(in)
      , m(law.A.rows())
      , qn(nominal.home)
      , seed(nominal.home)
      {
        const Eigen::Index n = nominal.na();
        if (law.A.cols() != m || law.B.rows() != m || law.B.cols() != n || law.C.rows() != n
            || law.C.cols() != m || law.D.rows() != n || law.D.cols() != n)
          throw std::invalid_argument("controller matrices have inconsistent shapes");
        s0.setZero(nominal.nv());
        qdn.resize(nominal.nv());
      }

      /// Torque at actuated (qa, qda) for reference row k and state x; e kept for the state
      /// map. Returns kChainOk or a law status (seed then holds the Newton seed of the closure).
      int torque(const Vec & qa, const Vec & qda, std::int64_t k, const Vec & x, Vec & tau,
                 double & value)
      {
        const auto r = in.R.row(k).transpose();
        e = r - qa;
        const double lam = p.lam;
        if (m > 0)
        {
          y.noalias() = p.C * x;
          y.noalias() += p.D * e;
          taubar = in.RDD.row(k).transpose() + 2.0 * lam * (in.RD.row(k).transpose() - qda)
                   + lam * lam * (e + y);
        }
        else  // FL alone: y = +0.0 exactly
          taubar = in.RDD.row(k).transpose() + 2.0 * lam * (in.RD.row(k).transpose() - qda)
                   + lam * lam * e;
        const ChainModel & cm = w.cm;
        seed = qn;
        for (Eigen::Index i = 0; i < cm.act.size(); ++i)
          qn[cm.act[i]] = qa[i];
        const int st = w.close(qn, in.closure_tol, in.max_iter, in.cond_limit, value);
        if (st)
        {
          qn = seed;  // a later call (none: the run stops) would seed from the last solution
          return st == 1 ? kChainLawSingular : kChainLawNoClose;
        }
        w.S_of(S);
        qdn.noalias() = S * qda;
        w.gamma(qn, qdn);
        sp = -w.Jp.partialPivLu().solve(w.g);
        for (Eigen::Index i = 0; i < cm.pas.size(); ++i)
          s0[cm.pas[i]] = sp[i];
        const Model & model = cm.tree.model;
        M = pinocchio::crba(model, w.data, CRef(qn));
        M.triangularView<Eigen::StrictlyLower>() = M.transpose();
        h = pinocchio::rnea(model, w.data, CRef(qn), CRef(qdn), CRef(s0));
        MS.noalias() = M * S;
        Mr.noalias() = S.transpose() * MS;
        tau.noalias() = Mr * taubar;
        tau.noalias() += S.transpose() * h;
        return kChainOk;
      }

      /// x+ = A x + B e with e of the last torque().
      void state_map(const Vec & x, Vec & out) const
      {
        out.noalias() = p.A * x;
        out.noalias() += p.B * e;
      }

      Vec seed;

    private:
      const ChainFLLaw & p;
      ChainWork w;
      const ChainInputs & in;
      Eigen::Index m;
      Vec qn, qdn, s0, sp, e, y, taubar, h;
      Mat S, M, MS, Mr;
    };

    /// The plant's step after RK4: drift check, projection, drift records, det J_p sign.
    int project(ChainWork & w, const ChainInputs & in, Vec & q, Vec & qd, double & sign,
                ChainResult & out)
    {
      const ChainModel & cm = w.cm;
      w.jacobian(q);  // phi at q, and Newton's first J
      const double gap = maxabs(w.phi);
      if (!(gap <= in.drift_bound))
      {
        out.value = gap;
        return kChainDrift;
      }
      out.drift = out.drift > gap ? out.drift : gap;  // Python's max(drift, gap)
      Vec qc = q;
      double cond = 0.0;
      const int st = w.close(qc, in.closure_tol, in.max_iter, in.cond_limit, cond, true);
      if (st)
      {
        out.value = cond;
        return st == 1 ? kChainPlantSingular : kChainPlantNoClose;
      }
      Vec qda(cm.act.size());
      for (Eigen::Index i = 0; i < cm.act.size(); ++i)
        qda[i] = qd[cm.act[i]];
      const Vec qdp = -w.Jp.partialPivLu().solve(w.Ja * qda);
      const double dv = maxabs(w.J * qd);  // J at the projected q, the unprojected qd
      out.drift_v = out.drift_v > dv ? out.drift_v : dv;
      const double det = w.Jp.determinant();
      q = qc;
      for (Eigen::Index i = 0; i < cm.pas.size(); ++i)
        qd[cm.pas[i]] = qdp[i];
      if (det * sign < 0.0)
      {
        out.value = w.cond();
        return kChainPlantCrossed;
      }
      sign = det;
      return kChainOk;
    }
  } // namespace

  ChainResult chain_rollout(const ChainModel & plant, const ChainModel & nominal,
                            const ChainFLLaw & law, const ChainInputs & in)
  {
    const Eigen::Index na = plant.na(), nv = plant.nv(), N = in.n_steps;
    if (nominal.na() != na)
      throw std::invalid_argument("the law's chain and the plant differ in actuated joints");
    if (N < 1 || in.substeps < 1 || in.R.rows() != N + 1 || in.RD.rows() != N + 1
        || in.RDD.rows() != N + 1 || in.R.cols() != na || in.RD.cols() != na
        || in.RDD.cols() != na || in.q0.size() != nv || in.qd0.size() != nv
        || in.x0.size() != law.A.rows())
      throw std::invalid_argument("closed-chain rollout: inputs of inconsistent sizes");
    ChainResult out;
    out.Q.setZero(N + 1, na);
    out.QD.setZero(N + 1, na);
    out.TAU.setZero(N + 1, na);
    ChainWork w(plant);
    ChainFLEval fl(law, nominal, in);
    Vec q = in.q0, qd = in.qd0, x = in.x0, xn(x.size()), qa(na), qda(na), tau(na);
    Vec u = Vec::Zero(nv), v2(nv), v3(nv), v4(nv), qs(nv), a1(nv), a2(nv), a3(nv), a4(nv);
    w.jacobian(q);
    double sign = w.Jp.determinant();
    const double h = in.h, h2 = 0.5 * h, h6 = h / 6.0;
    auto actuated = [&](const Vec & full, Vec & part) {
      for (Eigen::Index i = 0; i < na; ++i)
        part[i] = full[plant.act[i]];
    };
    actuated(q, qa);
    actuated(qd, qda);
    out.Q.row(0) = qa.transpose();
    out.QD.row(0) = qda.transpose();
    for (std::int64_t k = 0; k < N; ++k)
    {
      int st = fl.torque(qa, qda, k, x, tau, out.value);
      if (st)
      {
        out.status = st, out.step = k, out.seed = fl.seed, out.q = q, out.qd = qd;
        return out;
      }
      if (x.size())
      {
        fl.state_map(x, xn);
        x.swap(xn);
      }
      out.TAU.row(k) = tau.transpose();
      for (Eigen::Index i = 0; i < na; ++i)
        u[plant.act[i]] = tau[i];
      for (int s = 0; s < in.substeps; ++s)
      {
        a1 = w.acceleration(q, qd, u);
        v2 = qd + h2 * a1;
        qs = q + h2 * qd;
        a2 = w.acceleration(qs, v2, u);
        v3 = qd + h2 * a2;
        qs = q + h2 * v2;
        a3 = w.acceleration(qs, v3, u);
        v4 = qd + h * a3;
        qs = q + h * v3;
        a4 = w.acceleration(qs, v4, u);
        q = q + h6 * (qd + 2.0 * (v2 + v3) + v4);
        qd = qd + h6 * (a1 + 2.0 * (a2 + a3) + a4);
        st = project(w, in, q, qd, sign, out);
        if (st)
        {
          out.status = st, out.step = k, out.q = q, out.qd = qd;
          return out;
        }
      }
      actuated(q, qa);
      actuated(qd, qda);
      out.Q.row(k + 1) = qa.transpose();
      out.QD.row(k + 1) = qda.transpose();
    }
    out.TAU.row(N) = out.TAU.row(N - 1);
    out.q = q;
    out.qd = qd;
    return out;
  }

  std::tuple<int, std::int64_t, double> chain_check_reference(
    const ChainModel & cm, const RowMat & R, const Vec & seed, double tol, int max_iter,
    double cond_limit)
  {
    if (R.cols() != cm.na() || seed.size() != cm.nv())
      throw std::invalid_argument("R must have na columns and seed nv entries");
    ChainWork w(cm);
    Vec q = seed;
    double worst = 0.0, sign = 0.0, cond = 0.0;
    std::int64_t at = 0;
    for (Eigen::Index k = 0; k < R.rows(); ++k)
    {
      for (Eigen::Index i = 0; i < cm.act.size(); ++i)
        q[cm.act[i]] = R(k, i);
      if (w.close(q, tol, max_iter, cond_limit, cond))
        return {1, k, cond};
      const double det = w.Jp.determinant();
      if (cond > worst)
        worst = cond, at = k;
      if (sign != 0.0 && det * sign < 0.0)
        return {1, k, cond};
      sign = std::copysign(1.0, det);
    }
    return {0, at, worst};
  }

  double chain_kkt_timing(const ChainModel & plant, const Vec & q, const Vec & qd, const Vec & u,
                          std::int64_t calls)
  {
    if (q.size() != plant.nv() || qd.size() != plant.nv() || u.size() != plant.nv())
      throw std::invalid_argument("q, qd and u must have nv entries");
    ChainWork w(plant);
    double sink = 0.0;
    const auto t0 = std::chrono::steady_clock::now();
    for (std::int64_t i = 0; i < calls; ++i)
      sink += w.acceleration(q, qd, u)[0];
    const auto t1 = std::chrono::steady_clock::now();
    if (std::isnan(sink))
      return std::numeric_limits<double>::quiet_NaN();
    return std::chrono::duration<double>(t1 - t0).count();
  }
} // namespace rrr_pin
