// A plant's tree and its loop closure (tree.hpp): kinematics of the loop closure, Newton, exact
// KKT dynamics and the reference check, each in the order of the Python model
// (rrr_pin.model.closed_chain.ClosedChain).
#include "tree.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/SVD>

#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>

namespace rrr_pin
{
  namespace
  {
    const double kInf = std::numeric_limits<double>::infinity();
  } // namespace

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

  Tree::Tree(const std::string & serialized, const IVec & act_, const IVec & pas_,
             const Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> & loop_joints,
             const RowMat & loop_anchors, const IVec & rows_, const Vec & home_,
             double closure_tol_, int max_iter_, double cond_limit_, double drift_bound_)
  : tree(serialized)
  , joint_a(loop_joints.col(0))
  , joint_b(loop_joints.col(1))
  , rows(rows_)
  , act(act_)
  , pas(pas_)
  , home(home_)
  , closure_tol(closure_tol_)
  , max_iter(max_iter_)
  , cond_limit(cond_limit_)
  , drift_bound(drift_bound_)
  {
    const Model & m = tree.model;
    const Eigen::Index nc = loop_joints.rows();
    if (m.nq != m.nv)
      throw std::invalid_argument("tree: nq != nv (one coordinate per joint only)");
    if (loop_anchors.rows() != 2 * nc || loop_anchors.cols() != 3)
      throw std::invalid_argument("tree: loop_anchors must be (2 L, 3) for L loop_joints rows");
    anchor_a.resize(3, nc);
    anchor_b.resize(3, nc);
    for (Eigen::Index k = 0; k < nc; ++k)
    {
      anchor_a.col(k) = loop_anchors.row(2 * k).transpose();
      anchor_b.col(k) = loop_anchors.row(2 * k + 1).transpose();
      if (joint_a[k] < 0 || joint_a[k] >= m.njoints || joint_b[k] < 0 || joint_b[k] >= m.njoints)
        throw std::invalid_argument("tree: loop joint index out of range");
    }
    if (act.size() + pas.size() != m.nv || rows.size() != pas.size() || home.size() != m.nq)
      throw std::invalid_argument("tree: actuated, passive, rows or home of the wrong size");
    for (Eigen::Index i = 0; i < rows.size(); ++i)
      if (rows[i] < 0 || rows[i] >= 3 * nc)
        throw std::invalid_argument("tree: row index out of range");
    for (const IVec * idx : {&act, &pas})
      for (Eigen::Index i = 0; i < idx->size(); ++i)
        if ((*idx)[i] < 0 || (*idx)[i] >= m.nv)
          throw std::invalid_argument("tree: actuated or passive index out of range");
    if (nc == 0 && pas.size() > 0)
      throw std::invalid_argument("tree: passive coordinates need a loop closure");
  }

  Closure::Closure(const Tree & tree)
  : cm(tree)
  , data(tree.tree.model)
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

  void Closure::point(int joint, const Eigen::Ref<const Eigen::Vector3d> & t,
                      Eigen::Vector3d & p) const
  {
    const pinocchio::SE3 & oMi = data.oMi[static_cast<std::size_t>(joint)];
    p.noalias() = oMi.rotation() * t;
    p += oMi.translation();
  }

  void Closure::jacobian(const Vec & q)
  {
    pinocchio::computeJointJacobians(cm.tree.model, data, CRef(q));
    points();
  }

  void Closure::points()
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

  void Closure::gamma(const Vec & q, const Vec & qd)
  {
    pinocchio::forwardKinematics(cm.tree.model, data, CRef(q), CRef(qd), CRef(zero));
    gamma_points();
  }

  void Closure::gamma_points()
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

  double Closure::cond() const
  {
    if (Jp.size() == 0)
      return 1.0;
    Eigen::JacobiSVD<Mat> svd(Jp);
    const Vec & s = svd.singularValues();
    const double lo = s.minCoeff();
    return lo > 0.0 ? s.maxCoeff() / lo : kInf;
  }

  int Closure::close(Vec & q, double & cond_out, bool fresh)
  {
    for (int it = 0; it < cm.max_iter; ++it)
    {
      if (it || !fresh)
        jacobian(q);
      if (maxabs(phi) <= cm.closure_tol)
      {
        cond_out = cond();
        return cond_out <= cm.cond_limit ? 0 : 1;
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

  void Closure::S_of(Mat & Sout)
  {
    Sout.setZero(cm.nv(), cm.na());
    const Mat X = Jp.partialPivLu().solve(Ja);
    for (Eigen::Index i = 0; i < cm.act.size(); ++i)
      Sout(cm.act[i], i) = 1.0;
    for (Eigen::Index i = 0; i < cm.pas.size(); ++i)
      Sout.row(cm.pas[i]) = -X.row(i);
  }

  const Vec & Closure::acceleration(const Vec & q, const Vec & qd, const Vec & u)
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

  std::tuple<int, std::int64_t, double> check_reference(const Tree & tree, const RowMat & R)
  {
    if (R.cols() != tree.na())
      throw std::invalid_argument("R must have one column per actuated coordinate");
    if (tree.loops() == 0)
      return {0, 0, 1.0};  // every configuration of a serial tree is one
    Closure w(tree);
    Vec q = tree.home;
    double worst = 0.0, sign = 0.0, cond = 0.0;
    std::int64_t at = 0;
    for (Eigen::Index k = 0; k < R.rows(); ++k)
    {
      for (Eigen::Index i = 0; i < tree.act.size(); ++i)
        q[tree.act[i]] = R(k, i);
      if (w.close(q, cond))
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
} // namespace rrr_pin
