// Batched rollouts on generated dynamics (see batch.hpp): the lane loops. The generated
// structures they run on, compiled in or loaded at run time, are dyn_table.cpp's.
#include "batch.hpp"

#include <Eigen/LU>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <vector>

#include "batch_outputs.hpp"
#include "effects.hpp"
#include "rk4.hpp"

namespace rrr_pin
{
  namespace
  {
    /// The law's nominal model and the plants, structure-of-arrays derived vectors: the
    /// parameter-only expressions, computed once here (f.pre), not at every call.
    struct Models
    {
      const DynFunctions & f;
      int B, n;
      Lanes plant, nominal;  // (nd, B)

      Models(const DynFunctions & fns, const RowMat & P, const Vec & Pn)
      : f(fns)
      , B(static_cast<int>(P.rows()))
      , n(fns.nq)
      , plant(static_cast<std::size_t>(fns.nd) * B)
      , nominal(plant.size())
      {
        Lanes p(static_cast<std::size_t>(fns.np) * B), pn(p.size());
        for (int k = 0; k < f.np; ++k)
          for (int b = 0; b < B; ++b)
          {
            p[k * B + b] = P(b, k);
            pn[k * B + b] = Pn[k];
          }
        f.pre(B, p.data(), plant.data());
        f.pre(B, pn.data(), nominal.data());
      }
    };

    /// out = A x + Bu u for B plants (lanes: entry k of plant b at [k * B + b]): the state map
    /// of the batched laws, with u their K's input (e, or [e; qd]) of Bu.cols() entries.
    void lane_state_map(const Mat & A, const Mat & Bu, const double * x, const double * u, int B,
                        double * out)
    {
      const int m = static_cast<int>(A.rows()), w = static_cast<int>(Bu.cols());
      for (int l = 0; l < m; ++l)
        for (int b = 0; b < B; ++b)
        {
          double s = 0.0;
          for (int k = 0; k < m; ++k)
            s += A(l, k) * x[k * B + b];
          for (int k = 0; k < w; ++k)
            s += Bu(l, k) * u[k * B + b];
          out[l * B + b] = s;
        }
    }

    /// The batched form of a law: torque of every plant from its state and law state.
    template<class Law>
    struct BatchLaw;

    template<>
    struct BatchLaw<FLLaw>
    {
      const FLLaw & p;
      const Models & md;
      int B, n, m;
      Lanes e, y, taubar, M, tau;  // M: Mhat(q), filled by BatchLaw<FLAWLaw> when it clips

      BatchLaw(const FLLaw & law, const Models & models)
      : p(law)
      , md(models)
      , B(models.B)
      , n(models.n)
      , m(static_cast<int>(law.nx()))
      , e(n * B)
      , y(n * B)
      , taubar(n * B)
      , M(n * n * B)
      , tau(n * B)
      {
      }

      const Lanes & torque(
        const double * q, const double * qd, const double * r, const double * rd,
        const double * rdd, const double * x)
      {
        for (int j = 0; j < n; ++j)
          for (int b = 0; b < B; ++b)
            e[j * B + b] = r[j] - q[j * B + b];
        for (int j = 0; j < n; ++j)
          for (int b = 0; b < B; ++b)
          {
            double s = 0.0;
            for (int k = 0; k < n; ++k)
              s += p.D(j, k) * e[k * B + b];
            for (int l = 0; l < m; ++l)
              s += p.C(j, l) * x[l * B + b];
            y[j * B + b] = s;
          }
        for (int j = 0; j < n; ++j)
          for (int b = 0; b < B; ++b)
          {
            const double lam = p.lam[j];
            const int i = j * B + b;
            taubar[i] = rdd[j] + 2.0 * lam * (rd[j] - qd[i]) + lam * lam * (e[i] + y[i]);
          }
        // tau = Mhat(q) taubar + hhat(q, qd): one inverse-dynamics recursion (dyngen's id)
        md.f.id(B, md.nominal.data(), q, qd, taubar.data(), tau.data());
        return tau;
      }

      /// out = A x + B e (e of the last torque()).
      void state_map(const double * x, double * out) const
      {
        lane_state_map(p.A, p.B, x, e.data(), B, out);
      }

      static void model_calls(const Models & md, const double * q, const double * qd,
                              double * M, double * tau)
      {
        md.f.crba(md.B, md.nominal.data(), q, M);
        md.f.nle(md.B, md.nominal.data(), q, qd, tau);
      }
    };

    /// FLLaw's torque clipped to the limits, K conditioned on the clip (FLAWLaw, Hanus), per
    /// plant as FLAWLaw::Eval does: the correction only for plants where a joint clipped.
    template<>
    struct BatchLaw<FLAWLaw>
    {
      BatchLaw<FLLaw> fl;
      const FLAWLaw & p;
      int B, n, m;
      Lanes tau, dy;
      std::vector<char> clipped;
      Mat Mb;
      Vec rhs;

      BatchLaw(const FLAWLaw & law, const Models & models)
      : fl(law, models)
      , p(law)
      , B(models.B)
      , n(models.n)
      , m(static_cast<int>(law.nx()))
      , tau(n * B)
      , dy(n * B)
      , clipped(B, 0)
      , Mb(n, n)
      , rhs(n)
      {
      }

      const Lanes & torque(
        const double * q, const double * qd, const double * r, const double * rd,
        const double * rdd, const double * x)
      {
        const Lanes & raw = fl.torque(q, qd, r, rd, rdd, x);
        bool any = false;
        for (int b = 0; b < B; ++b)
        {
          bool c = false;
          for (int j = 0; j < n; ++j)
          {
            const int i = j * B + b;
            // Eigen's cwiseMax(-limit).cwiseMin(limit): std::max, then std::min.
            tau[i] = std::min(std::max(raw[i], -p.limit[j]), p.limit[j]);
            c = c || tau[i] != raw[i];
          }
          clipped[b] = c;
          any = any || c;
        }
        if (!any)
          return tau;
        // Mhat(q) only when a plant clipped (the raw torque came from one id recursion).
        fl.md.f.crba(B, fl.md.nominal.data(), q, fl.M.data());
        for (int b = 0; b < B; ++b)
        {
          if (!clipped[b])
            continue;
          for (int r_ = 0; r_ < n; ++r_)
          {
            rhs[r_] = tau[r_ * B + b] - raw[r_ * B + b];
            for (int k = 0; k < n; ++k)
              Mb(r_, k) = fl.M[(r_ * n + k) * B + b];
          }
          const Vec sol = Mb.partialPivLu().solve(rhs);
          for (int j = 0; j < n; ++j)
            dy[j * B + b] = sol[j] / (p.lam[j] * p.lam[j]);
        }
        return tau;
      }

      /// FLLaw's state map, plus L dy for the plants whose last torque() clipped.
      void state_map(const double * x, double * out) const
      {
        fl.state_map(x, out);
        for (int b = 0; b < B; ++b)
          if (clipped[b])
            for (int l = 0; l < m; ++l)
            {
              double s = 0.0;
              for (int k = 0; k < n; ++k)
                s += p.L(l, k) * dy[k * B + b];
              out[l * B + b] += s;
            }
      }

      static void model_calls(const Models & md, const double * q, const double * qd,
                              double * M, double * tau)
      {
        BatchLaw<FLLaw>::model_calls(md, q, qd, M, tau);
      }
    };

    template<>
    struct BatchLaw<PDLaw>
    {
      const PDLaw & p;
      const Models & md;
      int B, n, m = 0;
      Lanes e, g, tau;

      BatchLaw(const PDLaw & law, const Models & models)
      : p(law)
      , md(models)
      , B(models.B)
      , n(models.n)
      , e(n * B)
      , g(n * B)
      , tau(n * B)
      {
      }

      const Lanes & torque(
        const double * q, const double * qd, const double * r, const double * rd,
        const double *, const double *)
      {
        for (int j = 0; j < n; ++j)
          for (int b = 0; b < B; ++b)
            e[j * B + b] = r[j] - q[j * B + b];
        md.f.gravity(B, md.nominal.data(), q, g.data());
        for (int j = 0; j < n; ++j)
          for (int b = 0; b < B; ++b)
          {
            double s = 0.0, d = 0.0;
            for (int k = 0; k < n; ++k)
              s += p.Kp(j, k) * e[k * B + b];
            for (int k = 0; k < n; ++k)
              d += p.Kd(j, k) * (rd[k] - qd[k * B + b]);
            tau[j * B + b] = s + d + g[j * B + b];
          }
        return tau;
      }

      void state_map(const double *, double *) const {}

      static void model_calls(const Models & md, const double * q, const double *, double *,
                              double * tau)
      {
        md.f.gravity(md.B, md.nominal.data(), q, tau);
      }
    };

    /// TwoDOFLaw per plant, as TwoDOFLaw::Eval: tauhat = q + C x + D v, v = [e; qd],
    /// taubar = lam^2 (tauhat - q) - 2 lam qd, tau = Mhat(q) taubar + hhat(q, qd) by one
    /// inverse-dynamics recursion (dyngen's id, as BatchLaw<FLLaw>).
    template<>
    struct BatchLaw<TwoDOFLaw>
    {
      const TwoDOFLaw & p;
      const Models & md;
      int B, n, m;
      Lanes v, taubar, tau;  // v: (2n, B), [e; qd] of the last torque()

      BatchLaw(const TwoDOFLaw & law, const Models & models)
      : p(law)
      , md(models)
      , B(models.B)
      , n(models.n)
      , m(static_cast<int>(law.nx()))
      , v(2 * n * B)
      , taubar(n * B)
      , tau(n * B)
      {
      }

      const Lanes & torque(
        const double * q, const double * qd, const double * r, const double *,
        const double *, const double * x)
      {
        for (int j = 0; j < n; ++j)
          for (int b = 0; b < B; ++b)
          {
            v[j * B + b] = r[j] - q[j * B + b];
            v[(n + j) * B + b] = qd[j * B + b];
          }
        for (int j = 0; j < n; ++j)
          for (int b = 0; b < B; ++b)
          {
            const int i = j * B + b;
            // (q + C x) + D v, in the Python law's order
            double cx = 0.0, dv = 0.0;
            for (int l = 0; l < m; ++l)
              cx += p.C(j, l) * x[l * B + b];
            for (int k = 0; k < 2 * n; ++k)
              dv += p.D(j, k) * v[k * B + b];
            const double tauhat = q[i] + cx + dv;
            const double lam = p.lam[j];
            taubar[i] = lam * lam * (tauhat - q[i]) - 2.0 * lam * qd[i];
          }
        // tau = Mhat(q) taubar + hhat(q, qd): one inverse-dynamics recursion (dyngen's id)
        md.f.id(B, md.nominal.data(), q, qd, taubar.data(), tau.data());
        return tau;
      }

      /// out = A x + B v (v of the last torque()).
      void state_map(const double * x, double * out) const
      {
        lane_state_map(p.A, p.B, x, v.data(), B, out);
      }

      static void model_calls(const Models & md, const double * q, const double * qd,
                              double * M, double * tau)
      {
        BatchLaw<FLLaw>::model_calls(md, q, qd, M, tau);
      }
    };

    using BState = LaneState;
    using BRK4 = RK4Work<Lanes>;
    using batch_outputs::BatchOutputs;
    using batch_outputs::FigureOutputs;
    using batch_outputs::keep_torque;
    using batch_outputs::make_outputs;

    /// RK4 stage points and slopes of B plants of n joints and a law of m states, sized.
    BRK4 lane_work(std::size_t nB, std::size_t mB)
    {
      BRK4 w;
      for (BState * s : {&w.ys, &w.k1, &w.k2, &w.k3, &w.k4})
        s->q.resize(nB), s->qd.resize(nB), s->x.resize(mB);
      return w;
    }

    /// The ideal sampled plant: B arms driven by their held commands u.
    struct BatchPlant
    {
      const Models & md;
      Lanes u;
      Parts parts;

      void slope(const BState & y, int, BState & k)
      {
        k.q = y.qd;
        md.f.fd(md.B, md.plant.data(), y.q.data(), y.qd.data(), u.data(), k.qd.data());
      }
    };

    /// The sampled plant behind its drive train (effects.hpp's joint_torque_at, per joint and
    /// plant): B arms
    /// driven through the first-order actuator (a), the flexible joint (th, thd) and the
    /// friction of the effects, by their held commands u.
    struct BatchDriven
    {
      const Models & md;
      const Effects & fx;
      Lanes u, tj;
      Parts parts;

      BatchDriven(const Models & models, const Effects & effects)
      : md(models)
      , fx(effects)
      , u(static_cast<std::size_t>(models.n) * models.B)
      , tj(u.size())
      , parts(effects.parts())
      {
      }

      void slope(const BState & y, int, BState & k)
      {
        const int B = md.B, n = md.n;
        double ka = 0.0, kth = 0.0, kthd = 0.0;
        for (int j = 0; j < n; ++j)
          for (int b = 0; b < B; ++b)
          {
            const int i = j * B + b;
            tj[i] = fx.joint_torque_at(j, y.q[i], y.qd[i], fx.lags() ? y.a[i] : 0.0,
                                       fx.flexes() ? y.th[i] : 0.0,
                                       fx.flexes() ? y.thd[i] : 0.0, u[i], ka, kth, kthd);
            if (fx.lags())
              k.a[i] = ka;
            if (fx.flexes())
            {
              k.th[i] = kth;
              k.thd[i] = kthd;
            }
          }
        k.q = y.qd;
        md.f.fd(B, md.plant.data(), y.q.data(), y.qd.data(), tj.data(), k.qd.data());
      }

      /// effects.hpp's start_at, per joint and plant: at rest on the first command.
      void start(BState & y) const
      {
        const int B = md.B, n = md.n;
        double unused = 0.0;
        for (int j = 0; j < n; ++j)
          for (int b = 0; b < B; ++b)
          {
            const int i = j * B + b;
            fx.start_at(j, u[i], y.q[i], y.qd[i], fx.lags() ? y.a[i] : unused,
                        fx.flexes() ? y.th[i] : unused, fx.flexes() ? y.thd[i] : unused);
          }
      }
    };

    /// The sampled system of a run: the ideal plant, or the plant behind its drive train.
    template<class Sys>
    Sys make_system(const Models & md, const Effects & fx);

    template<>
    BatchPlant make_system<BatchPlant>(const Models & md, const Effects &)
    {
      return BatchPlant{md, Lanes(static_cast<std::size_t>(md.n) * md.B), Parts{}};
    }

    template<>
    BatchDriven make_system<BatchDriven>(const Models & md, const Effects & fx)
    {
      return BatchDriven(md, fx);
    }

    inline void start_system(BatchPlant &, BState &) {}
    inline void start_system(BatchDriven & sys, BState & y) { sys.start(y); }

    /// A continuous law and B arms, integrated together.
    template<class Law>
    struct BatchContinuous
    {
      const Models & md;
      BatchLaw<Law> & law;
      const RolloutInputs & in;
      Parts parts;
      std::int64_t k = 0;
      Lanes tau1;                     // torque of the step's first stage
      std::vector<int> bad_joint;     // per plant: first joint of a non-finite torque, or -1

      void slope(const BState & y, int point, BState & d)
      {
        const std::int64_t i = 2 * k + point;
        const Lanes & tau = law.torque(y.q.data(), y.qd.data(), in.R.row(i).data(),
                                       in.RD.row(i).data(), in.RDD.row(i).data(), y.x.data());
        const int B = md.B, n = md.n;
        for (int b = 0; b < B; ++b)
          if (bad_joint[b] < 0)
            for (int j = 0; j < n; ++j)
              if (!std::isfinite(tau[j * B + b]))
              {
                bad_joint[b] = j;
                break;
              }
        if (point == 0)
          tau1 = tau;
        if (parts.x)
          law.state_map(y.x.data(), d.x.data());
        d.q = y.qd;
        md.f.fd(B, md.plant.data(), y.q.data(), y.qd.data(), tau.data(), d.qd.data());
      }
    };

    /// Put a stopped plant back on its initial state (finite numbers, never recorded).
    void park(BState & y, int b, int B, const RolloutInputs & in)
    {
      const int n = static_cast<int>(in.q0.size()), m = static_cast<int>(in.x0.size());
      for (int j = 0; j < n; ++j)
      {
        y.q[j * B + b] = in.q0[j];
        y.qd[j * B + b] = in.qd0[j];
      }
      for (int l = 0; l < m; ++l)
        y.x[l * B + b] = in.x0[l];
    }

    BState initial(int B, const RolloutInputs & in)
    {
      const int n = static_cast<int>(in.q0.size()), m = static_cast<int>(in.x0.size());
      BState y;
      y.q.resize(n * B), y.qd.resize(n * B), y.x.resize(m * B);
      for (int b = 0; b < B; ++b)
        park(y, b, B, in);
      return y;
    }


    /// Sampled law on B plants: sensor -> law -> saturation -> delay -> actuator -> flexible
    /// joint -> plant with friction, as rollout.cpp's sampled_loop with these effects (the
    /// ideal plant without them; Sys: BatchPlant or BatchDriven).
    template<class Out, class Sys, class Law>
    auto sampled_loop(const Models & md, const Law & law, const RolloutInputs & in,
                      const RowMat & lower, const RowMat & upper, const Effects & fx)
    {
      const int B = md.B, n = md.n, m = static_cast<int>(law.nx());
      const std::int64_t N = in.n_steps;
      Out out = make_outputs<Out>(B, n, N, in);
      BatchLaw<Law> eval(law, md);
      Sys plant = make_system<Sys>(md, fx);
      BState y = initial(B, in);
      Lanes xn(m * B);
      BRK4 w = lane_work(n * B, 0);
      for (BState * s : {&y, &w.ys, &w.k1, &w.k2, &w.k3, &w.k4})  // the drive train's parts
      {
        s->a.assign(plant.parts.a ? n * B : 0, 0.0);
        s->th.assign(plant.parts.th ? n * B : 0, 0.0);
        s->thd.assign(plant.parts.th ? n * B : 0, 0.0);
      }
      std::vector<int> stopped;
      // The commands the delay reaches back to: row r (control step r) at hist[r % H].
      const std::int64_t H = fx.delay_steps > 0 ? fx.delay_steps / in.substeps + 2 : 0;
      std::vector<Lanes> hist(static_cast<std::size_t>(H), Lanes(n * B, 0.0));
      Lanes cmd(n * B);
      // The sensor (effects.hpp's sensed_q, sensed_qd): the law reads qm, qdm.
      const bool senses = fx.senses();
      Lanes qm(senses ? n * B : 0), qdm(senses ? n * B : 0);
      for (int b = 0; b < B; ++b)
        out.start(b, y);
      for (std::int64_t k = 0; k < N && out.n_alive > 0; ++k)
      {
        if (senses)
          for (int j = 0; j < n; ++j)
            for (int b = 0; b < B; ++b)
            {
              const int i = j * B + b;
              qm[i] = fx.sensed_q(k, j, y.q[i]);
              qdm[i] = fx.sensed_qd(k, j, y.qd[i]);
            }
        const Lanes & tau =
          eval.torque(senses ? qm.data() : y.q.data(), senses ? qdm.data() : y.qd.data(),
                      in.R.row(k).data(), in.RD.row(k).data(),
                      in.RDD.row(k).data(), y.x.data());
        if (m > 0)
        {
          eval.state_map(y.x.data(), xn.data());
          y.x.swap(xn);
        }
        cmd = tau;
        if (fx.saturates())  // effects.hpp's saturated, per joint and plant
          for (int j = 0; j < n; ++j)
            for (int b = 0; b < B; ++b)
              cmd[j * B + b] = fx.saturated(j, tau[j * B + b]);
        stopped.clear();
        for (int b = 0; b < B; ++b)
        {
          if (!out.alive[b])
            continue;
          int bad = -1;
          for (int j = 0; j < n && bad < 0; ++j)
            if (!std::isfinite(tau[j * B + b]))  // the law's own output, before saturation
              bad = j;
          out.torque(b, k, bad < 0 ? cmd : tau);
          if (bad >= 0)
          {
            out.kill(b, k, bad, kLawTorque);
            stopped.push_back(b);
          }
        }
        if (k == N - 1)
          keep_torque(out, cmd);
        plant.u = cmd;
        for (int b : stopped)
        {
          park(y, b, B, in);
          for (int j = 0; j < n; ++j)
            plant.u[j * B + b] = 0.0;
        }
        if (k == 0)
          start_system(plant, y);
        if (H > 0)
          hist[k % H] = plant.u;
        for (int s = 0; s < in.substeps; ++s)
        {
          if (H > 0)  // the command of row delayed_row(k, s) (row 0 before the first)
            plant.u = hist[fx.delayed_row(k, s, in.substeps) % H];
          plant.slope(y, 0, w.k1);
          rk4_rest(plant, y, in.h, w);
        }
        stopped.clear();
        out.record(k, y, lower, upper, in.vlim, stopped);
        for (int b : stopped)
          park(y, b, B, in);
      }
      out.hold_last_torque();
      return out.result();
    }

    template<class Out, class Law>
    auto continuous_loop(const Models & md, const Law & law, const RolloutInputs & in,
                         const RowMat & lower, const RowMat & upper)
    {
      const int B = md.B, n = md.n, m = static_cast<int>(law.nx());
      const std::int64_t N = in.n_steps;
      Out out = make_outputs<Out>(B, n, N, in);
      BatchLaw<Law> eval(law, md);
      Parts parts;
      parts.x = m > 0;
      BatchContinuous<Law> loop{md, eval, in, parts, 0, Lanes(n * B), std::vector<int>(B, -1)};
      BState y = initial(B, in);
      BRK4 w = lane_work(n * B, m * B);
      std::vector<int> stopped;
      for (int b = 0; b < B; ++b)
        out.start(b, y);
      for (std::int64_t k = 0; out.n_alive > 0; ++k)
      {
        loop.k = k;
        loop.slope(y, 0, w.k1);
        for (int b = 0; b < B; ++b)
          if (out.alive[b])
            out.torque(b, k, loop.tau1);
        if (k < N)
          rk4_rest(loop, y, in.h, w);
        stopped.clear();
        for (int b = 0; b < B; ++b)
          if (out.alive[b] && loop.bad_joint[b] >= 0)
          {
            out.kill(b, k, loop.bad_joint[b], kLawTorque);
            stopped.push_back(b);
          }
        if (k == N)
          break;
        out.record(k, y, lower, upper, in.vlim, stopped);
        for (int b : stopped)
        {
          park(y, b, B, in);
          loop.bad_joint[b] = -1;
        }
      }
      return out.result();
    }

    void check_batch(const DynFunctions & f, const RowMat & P, const Vec & Pn,
                     const RolloutInputs & in, Eigen::Index nx, const RowMat & lower,
                     const RowMat & upper)
    {
      const Eigen::Index n = f.nq, B = P.rows();
      if (B < 1 || B > kBatchMax)
        throw std::invalid_argument("a batch holds 1 to 16 plants");
      if (P.cols() != f.np || Pn.size() != f.np)
        throw std::invalid_argument("parameter vectors must have the structure's np entries");
      if (lower.rows() != B || upper.rows() != B || lower.cols() != n || upper.cols() != n)
        throw std::invalid_argument("limits must be (B, nq)");
      check_inputs(in, n, nx);
      if (in.q0.size() != n || in.qd0.size() != n)
        throw std::invalid_argument("state vectors must have nq entries");
    }
  } // namespace

  namespace
  {
    template<class Out, class Law>
    auto run_loop(const std::string & name, const RowMat & plant, const Vec & nominal,
                  const Law & law, const RolloutInputs & in, const RowMat & lower,
                  const RowMat & upper, const Effects * fx)
    {
      const DynFunctions & f = dyn_by_name(name);
      check_batch(f, plant, nominal, in, law.nx(), lower, upper);
      law.check(f.nq);
      const Effects none;
      if (fx)
      {
        if (!in.sampled)
          throw std::invalid_argument("plant effects need a sampled law");
        fx->check(f.nq, in.n_steps);
      }
      const Models md(f, plant, nominal);
      if (fx && fx->drives())
        return sampled_loop<Out, BatchDriven>(md, law, in, lower, upper, *fx);
      if (in.sampled)
        return sampled_loop<Out, BatchPlant>(md, law, in, lower, upper, fx ? *fx : none);
      return continuous_loop<Out>(md, law, in, lower, upper);
    }
  } // namespace

  template<class Law>
  BatchResult batch_rollout(
    const std::string & name, const RowMat & plant, const Vec & nominal, const Law & law,
    const RolloutInputs & in, const RowMat & lower, const RowMat & upper, const Effects * fx)
  {
    return run_loop<BatchOutputs>(name, plant, nominal, law, in, lower, upper, fx);
  }

  template<class Law>
  FigureResult batch_figures(
    const std::string & name, const RowMat & plant, const Vec & nominal, const Law & law,
    const RolloutInputs & in, const RowMat & lower, const RowMat & upper, const Effects * fx)
  {
    if (in.n_steps < 1)
      throw std::invalid_argument("batch_figures: n_steps must be >= 1");
    return run_loop<FigureOutputs>(name, plant, nominal, law, in, lower, upper, fx);
  }

  template<class Law>
  double batch_floor_timing(
    const std::string & name, const RowMat & plant, const Vec & nominal, bool sampled,
    int substeps, std::int64_t n_steps)
  {
    const DynFunctions & f = dyn_by_name(name);
    if (plant.rows() < 1 || plant.rows() > kBatchMax || plant.cols() != f.np
        || nominal.size() != f.np)
      throw std::invalid_argument("1 to 16 parameter rows of the structure's np entries");
    if (substeps < 1 || n_steps < 0)
      throw std::invalid_argument("substeps must be >= 1 and n_steps >= 0");
    const Models md(f, plant, nominal);
    const int B = md.B, n = md.n;
    Lanes q(n * B, 0.3), qd(n * B, 0.1), tau(n * B, 0.0), M(n * n * B), out(n * B);
    double sink = 0.0;
    const auto t0 = std::chrono::steady_clock::now();
    for (std::int64_t k = 0; k < n_steps; ++k)
    {
      const int calls = sampled ? 1 : 4, fds = sampled ? 4 * substeps : 1;
      for (int c = 0; c < calls; ++c)
      {
        BatchLaw<Law>::model_calls(md, q.data(), qd.data(), M.data(), tau.data());
        for (int s = 0; s < fds; ++s)
        {
          f.fd(B, md.plant.data(), q.data(), qd.data(), tau.data(), out.data());
          sink += out[0];
        }
      }
    }
    const auto t1 = std::chrono::steady_clock::now();
    if (!std::isfinite(sink))
      throw std::runtime_error("batch_floor_timing: non-finite result");
    return std::chrono::duration<double>(t1 - t0).count();
  }

#define RRR_PIN_BATCH_INSTANCE(Law) RRR_PIN_BATCH_LAW(Law, )
  RRR_PIN_LAWS(RRR_PIN_BATCH_INSTANCE)
#undef RRR_PIN_BATCH_INSTANCE
} // namespace rrr_pin
