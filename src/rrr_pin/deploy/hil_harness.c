/* The real-time harness of `rrr-pin hil` (rrr_pin.deploy.hil): an exported controller in its own
 * process at a fixed rate against the simulated arm in another, through shared memory.
 *
 * Hand-written: no kept library runs an exported C law against a simulated arm across two
 * processes with an absolute-deadline clock; this file is that loop and nothing more.
 *
 *   rrr_pin_hil hil|offline SETTINGS OUT [HOLDS]
 *
 * SETTINGS (text, one number per token): cycles, clock period [ns], law period Ts [s], the
 * transport delay d [law periods], the velocity bound [rad/s] of the divergence test, the
 * actuator bandwidth wa [rad/s] (0: none) and the Coulomb smoothing speed v_eps [rad/s], then
 * per joint home, amp, freq [Hz], phase (the reference r = home + amp sin(2 pi freq t + phase)),
 * q0, qd0, the joint limits lower, upper [rad] (widened) of the divergence test, and the
 * friction Fv [N m s/rad], Fc [N m]. OUT (binary): per cycle k the measured q[n] at tick k (the state the law read),
 * the torque applied on [k Ts, (k+1) Ts) tau[n], and in hil mode the int64 nanoseconds
 * wake - deadline, done - deadline (the torque written), step (ctrl_step alone), and the flags
 * missed (torque written after the next tick: the plant held the previous one) and plant_late
 * (the state was not there at the tick). A header line of text goes to stdout. HOLDS (offline
 * only, one byte per cycle): the cycles whose torque the arm did not apply (the missed deadlines
 * of a real-time run), replayed: the offline loop then equals that run bit for bit.
 *
 * The plant: the nominal model of the export (its dynamics.h: M(q), h(q, qd)), forward dynamics
 * qdd = M^-1 (tau - h) by Gaussian elimination with partial pivoting, one classical RK4 step of Ts
 * per cycle with the torque held (zero-order hold), as rrr_pin's Python engine integrates.
 * The torque the joints receive is the command of d cycles before (a transport delay; before
 * the first d cycles, the first command, the loop taken at rest on it as rrr_pin's effects do),
 * plus what a drive adds under the export's torque convention (ctrl_removed_torque: Ghat(q) at
 * every RK4 stage when the command excludes gravity, as a drive compensates continuously).
 * The plant's effects as rrr_pin.control.effects writes them, in the same order and RK4 stages:
 * a first-order actuator a' = wa (u - a) (a = u0 at t = 0) and joint friction
 * Fv qd + Fc tanh(qd / v_eps) opposing the motion.
 * Divergence, as rrr_pin's engines define it: after a cycle's RK4 step, a q or qd not finite,
 * |qd| above the bound or q outside the widened limits; the loop stops there and the header
 * says "diverged K" (the cycle whose step diverged; -1: none).
 * Both processes end when their parent ends (PR_SET_PDEATHSIG, SIGKILL): a killed rrr-pin hil
 * leaves no real-time process behind.
 * The controller: on each absolute deadline t0 + k * period (clock_nanosleep, CLOCK_MONOTONIC,
 * TIMER_ABSTIME) it reads the state, calls ctrl_step and writes the torque. SCHED_FIFO (priority
 * 80 for the controller, 70 for the arm) and mlockall are asked for; whether they were granted
 * is printed. Neither process spins for long: the arm sleeps until the tick, then both poll the
 * other's counter with 5 us naps.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <sched.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#ifdef __linux__
#include <sys/prctl.h>
#endif
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "controller.h"
#include "dynamics.h"

#define N CTRL_NQ

typedef struct settings {
    long cycles;
    long period_ns;
    double Ts;
    long delay;
    double vmax;
    double wa;   /* actuator bandwidth [rad/s]; 0: none */
    double veps; /* Coulomb smoothing speed [rad/s] */
    int friction;
    double home[N], amp[N], freq[N], phase[N], q0[N], qd0[N], lower[N], upper[N], fv[N], fc[N];
} settings;

/* The plant's effects other than the delay, read once (rk4 and acceleration read them). */
static const settings *fx;

/* End this process when its parent ends (Linux); 0 if the parent is already gone. */
static int die_with_parent(pid_t parent)
{
#ifdef __linux__
    if (prctl(PR_SET_PDEATHSIG, SIGKILL) != 0) {
        return 0;
    }
#endif
    return parent <= 0 || getppid() == parent;
}

/* What the two processes share (one page-aligned anonymous mapping made before fork). */
typedef struct shared {
    _Atomic long state_seq; /* cycle whose state (q, qd, r, rd, rdd) is published */
    _Atomic long tau_seq;   /* cycle whose torque is published */
    _Atomic int go;         /* controller ready (1), failed (-1) */
    int sched_fifo, mlocked, ctrl_rc;
    int64_t t0;
    double q[N], qd[N], r[N], rd[N], rdd[N];
    double tau[N];
    int64_t tau_done; /* absolute time the torque was written [ns] */
} shared;

/* Per-cycle record of the controller's timing (shared; written by the controller). */
typedef struct timing {
    int64_t wake, done, step;
    int32_t plant_late, pad;
} timing;

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static void sleep_until(int64_t t)
{
    struct timespec ts;
    ts.tv_sec = (time_t)(t / 1000000000LL);
    ts.tv_nsec = (long)(t % 1000000000LL);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
    }
}

static void reference(const settings *s, double t, double r[N], double rd[N], double rdd[N])
{
    int i;
    for (i = 0; i < N; ++i) {
        double w = 2.0 * M_PI * s->freq[i];
        double a = w * t + s->phase[i];
        double sn = sin(a), cs = cos(a);
        r[i] = s->home[i] + s->amp[i] * sn;
        rd[i] = s->amp[i] * w * cs;
        rdd[i] = -s->amp[i] * w * w * sn;
    }
}

/* qdd = M^-1 (tau - h): Gaussian elimination with partial pivoting. */
static void acceleration(const double q[N], const double qd[N], const double tau[N],
                         double qdd[N])
{
    double a[N * N], h[N];
    int i, j, k;
    ctrl_dyn_crba(q, a);
    ctrl_dyn_nle(q, qd, h);
    for (i = 0; i < N; ++i) {
        double tj = tau[i];
        if (fx->friction) { /* the drive train's torque minus friction, then the arm */
            tj = tj - (fx->fv[i] * qd[i] + fx->fc[i] * tanh(qd[i] / fx->veps));
        }
        qdd[i] = tj - h[i];
    }
#if CTRL_COMMAND_REMOVES_GRAVITY || CTRL_COMMAND_REMOVES_FRICTION
    {
        double added[N];
        ctrl_removed_torque(q, qd, added); /* what the drive adds to the command */
        for (i = 0; i < N; ++i) {
            qdd[i] += added[i];
        }
    }
#endif
    for (k = 0; k < N; ++k) {
        int p = k;
        for (i = k + 1; i < N; ++i) {
            if (fabs(a[i * N + k]) > fabs(a[p * N + k])) {
                p = i;
            }
        }
        if (p != k) {
            double t;
            for (j = 0; j < N; ++j) {
                t = a[k * N + j];
                a[k * N + j] = a[p * N + j];
                a[p * N + j] = t;
            }
            t = qdd[k];
            qdd[k] = qdd[p];
            qdd[p] = t;
        }
        for (i = k + 1; i < N; ++i) {
            double f = a[i * N + k] / a[k * N + k];
            for (j = k + 1; j < N; ++j) {
                a[i * N + j] -= f * a[k * N + j];
            }
            qdd[i] -= f * qdd[k];
        }
    }
    for (i = N - 1; i >= 0; --i) {
        double acc = qdd[i];
        for (j = i + 1; j < N; ++j) {
            acc -= a[i * N + j] * qdd[j];
        }
        qdd[i] = acc / a[i * N + i];
    }
}

/* One classical RK4 step of h with the command u held, in the order of rrr_pin's Python engine
 * (rrr_pin.control.effects.PlantEffects.rk4): with an actuator (wa > 0) its output act is a
 * state integrated with the arm; without, the joints receive u. */
static void rk4(double x[N], double v[N], double act[N], const double u[N], double h)
{
    double a1[N], a2[N], a3[N], a4[N], v2[N], v3[N], v4[N], xs[N];
    double b1[N], b2[N], b3[N], b4[N], as[N];
    double h2 = 0.5 * h, h6 = h / 6.0, wa = fx->wa;
    int i;
    const double *t1 = wa > 0.0 ? act : u;
    for (i = 0; i < N; ++i) {
        b1[i] = wa > 0.0 ? wa * (u[i] - act[i]) : 0.0;
    }
    acceleration(x, v, t1, a1);
    for (i = 0; i < N; ++i) {
        v2[i] = v[i] + h2 * a1[i];
        xs[i] = x[i] + h2 * v[i];
        as[i] = wa > 0.0 ? act[i] + h2 * b1[i] : u[i];
        b2[i] = wa > 0.0 ? wa * (u[i] - as[i]) : 0.0;
    }
    acceleration(xs, v2, as, a2);
    for (i = 0; i < N; ++i) {
        v3[i] = v[i] + h2 * a2[i];
        xs[i] = x[i] + h2 * v2[i];
        as[i] = wa > 0.0 ? act[i] + h2 * b2[i] : u[i];
        b3[i] = wa > 0.0 ? wa * (u[i] - as[i]) : 0.0;
    }
    acceleration(xs, v3, as, a3);
    for (i = 0; i < N; ++i) {
        v4[i] = v[i] + h * a3[i];
        xs[i] = x[i] + h * v3[i];
        as[i] = wa > 0.0 ? act[i] + h * b3[i] : u[i];
        b4[i] = wa > 0.0 ? wa * (u[i] - as[i]) : 0.0;
    }
    acceleration(xs, v4, as, a4);
    for (i = 0; i < N; ++i) {
        x[i] = x[i] + h6 * (v[i] + 2.0 * (v2[i] + v3[i]) + v4[i]);
        v[i] = v[i] + h6 * (a1[i] + 2.0 * (a2[i] + a3[i]) + a4[i]);
        if (wa > 0.0) {
            act[i] = act[i] + h6 * (b1[i] + 2.0 * (b2[i] + b3[i]) + b4[i]);
        }
    }
}

static int read_settings(const char *path, settings *s)
{
    FILE *f = fopen(path, "r");
    int i, ok;
    if (!f) {
        return 0;
    }
    ok = fscanf(f, "%ld %ld %lf %ld %lf %lf %lf", &s->cycles, &s->period_ns, &s->Ts,
                &s->delay, &s->vmax, &s->wa, &s->veps) == 7;
    s->friction = 0;
    for (i = 0; ok && i < N; ++i) {
        ok = fscanf(f, "%lf %lf %lf %lf %lf %lf %lf %lf %lf %lf", &s->home[i], &s->amp[i],
                    &s->freq[i], &s->phase[i], &s->q0[i], &s->qd0[i], &s->lower[i],
                    &s->upper[i], &s->fv[i], &s->fc[i]) == 10;
        s->friction = s->friction || (ok && (s->fv[i] != 0.0 || s->fc[i] != 0.0));
    }
    fclose(f);
    return ok && s->cycles > 0 && s->period_ns > 0 && s->Ts > 0.0 && s->delay >= 0
           && s->wa >= 0.0 && s->veps > 0.0;
}

/* The divergence test of rrr_pin's engines (rrr_pin.sim.trajectory.diverged_joint). */
static int diverged(const settings *s, const double x[N], const double v[N])
{
    int i;
    for (i = 0; i < N; ++i) {
        if (!isfinite(x[i]) || !isfinite(v[i]) || fabs(v[i]) > s->vmax || x[i] < s->lower[i]
            || x[i] > s->upper[i]) {
            return 1;
        }
    }
    return 0;
}

/* The transport delay line: the command the drive received at each of the last d + 1 cycles.
 * line_push stores cycle k's and returns the one the joints get, cycle k - d's (the first
 * command before it exists). */
static double *line;

static const double *line_push(const settings *s, long k, const double cmd[N])
{
    int i;
    long slot = k % (s->delay + 1);
    for (i = 0; i < N; ++i) {
        line[slot * N + i] = cmd[i];
    }
    if (k < s->delay) {
        return line; /* slot 0: the first command */
    }
    return line + ((k - s->delay) % (s->delay + 1)) * N;
}

/* Whether the other process is alive: the controller asks for its parent (the arm), the arm
 * for its child (the controller). */
/* One law period of the arm, the same in the offline and the real-time loops: the torque held
 * goes through the delay line, the one the joints get is recorded in tau_row, the actuator
 * starts at rest on the first command, and the arm advances by one RK4 period. */
static void plant_period(const settings *s, long k, const double held[N], double x[N],
                         double v[N], double act[N], double tau_row[N])
{
    const double *applied = line_push(s, k, held);
    int i;
    for (i = 0; i < N; ++i) {
        tau_row[i] = applied[i];
        if (k == 0) {
            act[i] = applied[i]; /* the actuator at rest on the first command */
        }
    }
    rk4(x, v, act, applied, s->Ts);
}

static pid_t parent_pid, child_pid;

static int peer_alive(void)
{
    if (child_pid > 0) {
        return waitpid(child_pid, NULL, WNOHANG) == 0;
    }
    return getppid() == parent_pid;
}

/* Spin briefly, then nap 5 us at a time, until *seq reaches k; 0 if the other process died
 * meanwhile (asked every 10 ms of naps: a stalled peer is waited for, a dead one is not). */
static int wait_for(_Atomic long *seq, long k)
{
    const struct timespec nap = {0, 5000};
    long spins = 0;
    while (atomic_load_explicit(seq, memory_order_acquire) < k) {
        if (++spins < 500) {
            continue;
        }
        if (spins % 2000 == 0 && !peer_alive()) {
            return 0;
        }
        nanosleep(&nap, NULL);
    }
    return 1;
}

/* SCHED_FIFO at priority and every page locked, when permitted; bit 0: FIFO, bit 1: locked. */
static int real_time(int priority)
{
    struct sched_param sp;
    memset(&sp, 0, sizeof sp);
    sp.sched_priority = priority;
    return (sched_setscheduler(0, SCHED_FIFO, &sp) == 0)
           | ((mlockall(MCL_CURRENT | MCL_FUTURE) == 0) << 1);
}

static void controller(const settings *s, shared *sh, timing *tm)
{
    double q[N], qd[N], r[N], rd[N], rdd[N], tau[N];
    ctrl_state st;
    long k;
    int i, rt;
    if (!die_with_parent(parent_pid)) {
        sh->ctrl_rc = -2;
        return;
    }
    rt = real_time(80);
    sh->sched_fifo = rt & 1;
    sh->mlocked = (rt >> 1) & 1;
    ctrl_reset(&st); /* Pinocchio's workspace for this thread, before the loop */
    atomic_store(&sh->go, 1);
    for (k = 0; k < s->cycles; ++k) {
        int64_t deadline = sh->t0 + k * s->period_ns, wake, start, done;
        int late;
        sleep_until(deadline);
        wake = now_ns();
        late = atomic_load_explicit(&sh->state_seq, memory_order_acquire) < k;
        if (late && !wait_for(&sh->state_seq, k)) {
            sh->ctrl_rc = -2; /* the arm's process died */
            return;
        }
        for (i = 0; i < N; ++i) {
            q[i] = sh->q[i];
            qd[i] = sh->qd[i];
            r[i] = sh->r[i];
            rd[i] = sh->rd[i];
            rdd[i] = sh->rdd[i];
        }
        start = now_ns();
        sh->ctrl_rc = ctrl_step(&st, q, qd, r, rd, rdd, tau);
        done = now_ns();
        for (i = 0; i < N; ++i) {
            sh->tau[i] = tau[i];
        }
        sh->tau_done = done;
        atomic_store_explicit(&sh->tau_seq, k + 1, memory_order_release);
        tm[k].wake = wake - deadline;
        tm[k].done = done - deadline;
        tm[k].step = done - start;
        tm[k].plant_late = late;
        if (sh->ctrl_rc != CTRL_OK) {
            return;
        }
    }
}

int main(int argc, char **argv)
{
    settings s;
    shared *sh;
    timing *tm;
    double *Q, *TAU, x[N], v[N], held[N], act[N];
    FILE *out;
    long k, missed = 0, diverged_at = -1;
    int i, offline, status = 0, plant_rt = 0;
    const char *parent = getenv("RRR_PIN_HIL_PARENT");
    pid_t child = -1;
    unsigned char *holds = NULL;
    if (argc < 4 || argc > 5 || (strcmp(argv[1], "hil") && strcmp(argv[1], "offline"))
        || (argc == 5 && strcmp(argv[1], "offline"))) {
        fprintf(stderr, "usage: %s hil|offline SETTINGS OUT [HOLDS]\n", argv[0]);
        return 2;
    }
    offline = !strcmp(argv[1], "offline");
    if (!die_with_parent(parent ? (pid_t)atol(parent) : 0)) {
        return 6; /* rrr-pin hil ended before this process started */
    }
    memset(&s, 0, sizeof s);
    if (!read_settings(argv[2], &s)) {
        fprintf(stderr, "%s: cannot read the settings of %d joints\n", argv[2], N);
        return 2;
    }
    Q = malloc(sizeof(double) * N * (size_t)s.cycles);
    TAU = malloc(sizeof(double) * N * (size_t)s.cycles);
    sh = mmap(NULL, sizeof *sh, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    tm = mmap(NULL, sizeof *tm * (size_t)s.cycles, PROT_READ | PROT_WRITE,
              MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    line = calloc((size_t)(s.delay + 1) * N, sizeof(double));
    if (!Q || !TAU || !line || sh == MAP_FAILED || tm == MAP_FAILED) {
        fprintf(stderr, "out of memory for %ld cycles\n", s.cycles);
        return 3;
    }
    memset(tm, 0, sizeof *tm * (size_t)s.cycles); /* touch every page before the loop */
    memset(Q, 0, sizeof(double) * N * (size_t)s.cycles);
    memset(TAU, 0, sizeof(double) * N * (size_t)s.cycles);
    memset(sh, 0, sizeof *sh);
    if (argc == 5) {
        FILE *f = fopen(argv[4], "rb");
        holds = calloc((size_t)s.cycles, 1);
        if (!f || !holds || fread(holds, 1, (size_t)s.cycles, f) != (size_t)s.cycles) {
            fprintf(stderr, "%s: cannot read %ld hold flags\n", argv[4], s.cycles);
            return 2;
        }
        fclose(f);
    }
    fx = &s;
    for (i = 0; i < N; ++i) {
        x[i] = s.q0[i];
        v[i] = s.qd0[i];
        held[i] = 0.0;
    }
    atomic_store(&sh->state_seq, -1);
    atomic_store(&sh->tau_seq, 0);
    if (offline) {
        ctrl_state st;
        ctrl_reset(&st);
        for (k = 0; k < s.cycles; ++k) {
            double r[N], rd[N], rdd[N], tau[N];
            reference(&s, (double)k * s.Ts, r, rd, rdd);
            if (ctrl_step(&st, x, v, r, rd, rdd, tau) != CTRL_OK) {
                fprintf(stderr, "ctrl_step failed at cycle %ld\n", k);
                return 4;
            }
            if (holds && holds[k]) {
                ++missed; /* replayed: the arm holds the previous torque */
            } else {
                for (i = 0; i < N; ++i) {
                    held[i] = tau[i];
                }
            }
            for (i = 0; i < N; ++i) {
                Q[k * N + i] = x[i];
            }
            plant_period(&s, k, held, x, v, act, &TAU[k * N]);
            if (diverged(&s, x, v)) {
                diverged_at = k;
                break;
            }
        }
    } else {
        sh->t0 = now_ns() + 100000000LL; /* first tick 100 ms from now */
        parent_pid = getpid();
        child = fork();
        if (child < 0) {
            perror("fork");
            return 3;
        }
        if (child == 0) {
            controller(&s, sh, tm);
            _exit(sh->ctrl_rc == CTRL_OK ? 0 : 1);
        }
        child_pid = child;
        plant_rt = real_time(70); /* the arm: below the controller */
        for (k = 0; k < s.cycles; ++k) {
            const int64_t deadline = sh->t0 + k * s.period_ns;
            reference(&s, (double)k * s.Ts, sh->r, sh->rd, sh->rdd);
            for (i = 0; i < N; ++i) {
                sh->q[i] = x[i];
                sh->qd[i] = v[i];
                Q[k * N + i] = x[i];
            }
            atomic_store_explicit(&sh->state_seq, k, memory_order_release);
            sleep_until(deadline); /* no torque of cycle k before its tick */
            if (!wait_for(&sh->tau_seq, k + 1)) {
                fprintf(stderr, "the controller's process ended before the torque of cycle %ld "
                        "(rc %d)\n", k, sh->ctrl_rc);
                status = 5;
                child = -1; /* already reaped */
                break;
            }
            if (sh->ctrl_rc != CTRL_OK) {
                fprintf(stderr, "ctrl_step failed (%d) at cycle %ld\n", sh->ctrl_rc, k);
                status = 4;
                break;
            }
            /* written after the next tick: the drive held the previous torque for this period */
            if (sh->tau_done - deadline > s.period_ns) {
                ++missed;
            } else {
                for (i = 0; i < N; ++i) {
                    held[i] = sh->tau[i];
                }
            }
            plant_period(&s, k, held, x, v, act, &TAU[k * N]);
            if (diverged(&s, x, v)) {
                diverged_at = k;
                kill(child, SIGKILL); /* the controller has nothing left to control */
                break;
            }
        }
        if (status && child > 0) {
            kill(child, SIGKILL);
        }
        if (child > 0) {
            waitpid(child, NULL, 0);
        }
        if (status) {
            return status;
        }
    }
    out = fopen(argv[3], "wb");
    if (!out) {
        perror(argv[3]);
        return 3;
    }
    fwrite(Q, sizeof(double), (size_t)N * (size_t)s.cycles, out);
    fwrite(TAU, sizeof(double), (size_t)N * (size_t)s.cycles, out);
    if (!offline) {
        fwrite(tm, sizeof *tm, (size_t)s.cycles, out);
    }
    fclose(out);
    printf("cycles %ld missed %ld sched_fifo %d mlockall %d plant_sched_fifo %d "
           "plant_mlockall %d diverged %ld\n", s.cycles, missed, offline ? 0 : sh->sched_fifo,
           offline ? 0 : sh->mlocked, plant_rt & 1, (plant_rt >> 1) & 1, diverged_at);
    return 0;
}
