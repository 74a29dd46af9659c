/* A program that waits in every way the virtual clock intercepts and prints, for each wait, the
 * virtual CLOCK_MONOTONIC time it ended at (ns since its start) and what it returned:
 *   <label> <elapsed_ns> <result>
 * Run by tests/emulator/firmware/virtual_clock_test.cc with libwheelhil_vtime.so preloaded and
 * the test as the clock's host. argv[1] picks the case. */
#define _GNU_SOURCE
#include <dirent.h>
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <linux/futex.h>
#include <net/if.h>
#include <poll.h>
#include <pthread.h>
#include <semaphore.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/resource.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <sys/time.h>
#include <sys/timerfd.h>
#include <sys/timex.h>
#include <time.h>
#include <unistd.h>

static int64_t g_start;

static int64_t mono(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static void report(const char* label, long result) {
  printf("%s %lld %ld\n", label, (long long)(mono() - g_start), result);
  fflush(stdout);
}

static pthread_mutex_t g_m = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t g_c = PTHREAD_COND_INITIALIZER;
static int g_flag = 0;

static void* signaller(void* arg) {
  (void)arg;
  usleep(10000);
  pthread_mutex_lock(&g_m);
  g_flag = 1;
  pthread_cond_signal(&g_c);
  pthread_mutex_unlock(&g_m);
  return NULL;
}

static sem_t g_sem;
static pthread_mutex_t g_held = PTHREAD_MUTEX_INITIALIZER;

static void* poster(void* arg) {
  (void)arg;
  usleep(5000);
  sem_post(&g_sem);
  return NULL;
}

static void* holder(void* arg) {
  pthread_mutex_lock(&g_held);
  usleep((useconds_t)(intptr_t)arg);
  pthread_mutex_unlock(&g_held);
  return NULL;
}

static struct timespec in_ms(clockid_t c, long ms) {
  struct timespec t;
  clock_gettime(c, &t);
  t.tv_nsec += ms * 1000000L;
  while (t.tv_nsec >= 1000000000L) {
    t.tv_sec += 1;
    t.tv_nsec -= 1000000000L;
  }
  return t;
}

static uint32_t g_word = 0;

static void* futex_waker(void* arg) {
  (void)arg;
  usleep(2000);
  __atomic_store_n(&g_word, 1, __ATOMIC_SEQ_CST);
  syscall(SYS_futex, &g_word, FUTEX_WAKE_PRIVATE, 1, NULL, NULL, 0);
  return NULL;
}

static volatile sig_atomic_t g_alarms = 0;
static void on_alarm(int sig) {
  (void)sig;
  g_alarms++;
}

static sem_t g_fired;
static void on_timer_thread(union sigval v) {
  if (v.sival_int == 42) sem_post(&g_fired);
}

static int64_t realtime_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return (int64_t)ts.tv_sec;
}

/* Waits that must never end ("forever": tv_sec = LONG_MAX); each sets its flag if it does. */
static volatile int g_ended[6];
static void* sleep_forever(void* arg) {
  (void)arg;
  struct timespec req = {LONG_MAX, 999999999};
  nanosleep(&req, NULL);
  g_ended[0] = 1;
  return NULL;
}
static void* abs_sleep_forever(void* arg) {
  (void)arg;
  struct timespec abs = {LONG_MAX, 0};
  clock_nanosleep(CLOCK_REALTIME, TIMER_ABSTIME, &abs, NULL);
  g_ended[1] = 1;
  return NULL;
}
static void* cond_forever(void* arg) {
  (void)arg;
  pthread_mutex_t m = PTHREAD_MUTEX_INITIALIZER;
  pthread_cond_t c = PTHREAD_COND_INITIALIZER;
  struct timespec abs = {LONG_MAX, 0};
  pthread_mutex_lock(&m);
  int rc;
  do rc = pthread_cond_timedwait(&c, &m, &abs);
  while (rc == 0);
  g_ended[2] = 1;
  return NULL;
}
static void* ppoll_forever(void* arg) {
  (void)arg;
  struct timespec t = {LONG_MAX, 0};
  ppoll(NULL, 0, &t, NULL);
  g_ended[3] = 1;
  return NULL;
}
static void* select_forever(void* arg) {
  (void)arg;
  struct timeval tv = {LONG_MAX, 0};
  select(0, NULL, NULL, NULL, &tv);
  g_ended[4] = 1;
  return NULL;
}
static void* sem_forever(void* arg) {
  (void)arg;
  sem_t s;
  sem_init(&s, 0, 0);
  struct timespec abs = {LONG_MAX, 0};
  sem_timedwait(&s, &abs);
  g_ended[5] = 1;
  return NULL;
}

/* A SIGALRM handler that sleeps: its wait nests inside the one it interrupted. */
static void on_alarm_sleeping(int sig) {
  (void)sig;
  usleep(5000);
  report("handler_slept", 0);
}

/* A thread that waits with timeouts while another closes every descriptor it did not open. */
static void* timed_polls(void* arg) {
  (void)arg;
  for (int i = 0; i < 3; ++i) report(i == 0 ? "thread_poll1" : i == 1 ? "thread_poll2" : "thread_poll3",
                                     poll(NULL, 0, 10));
  return NULL;
}

/* Puts a pipe on every eventfd number of this process (the library's wake-ups among them). */
static int dup2_onto_eventfds(void) {
  int p[2], n = 0;
  if (pipe(p) != 0) return -1;
  DIR* d = opendir("/proc/self/fd");
  if (d == NULL) return -1;
  int fds[64], count = 0;
  struct dirent* e;
  while ((e = readdir(d)) != NULL && count < 64) {
    char path[300], target[64];
    snprintf(path, sizeof(path), "/proc/self/fd/%s", e->d_name);
    const ssize_t len = readlink(path, target, sizeof(target) - 1);
    if (len <= 0) continue;
    target[len] = '\0';
    if (strstr(target, "eventfd") != NULL) fds[count++] = atoi(e->d_name);
  }
  closedir(d);
  for (int i = 0; i < count; ++i) {
    if (dup2(p[0], fds[i]) == fds[i]) ++n;
  }
  return n;
}

static void* first_wait_without_fds(void* arg) {
  (void)arg;
  report("nofd_poll", poll(NULL, 0, 7));
  struct timeval tv = {0, 5000};
  report("nofd_select", select(0, NULL, NULL, NULL, &tv));
  return NULL;
}

/* Runahead: lines kept in memory and written at the end, so that no thread sleeps in the
 * kernel on a file (outside the library's waits) in between. */
static char g_lines[4096];
static size_t g_used;
static pthread_mutex_t g_lines_lock = PTHREAD_MUTEX_INITIALIZER;
static void report_later(const char* label, long result) {
  const long long t = (long long)(mono() - g_start);
  pthread_mutex_lock(&g_lines_lock);
  const int n =
      snprintf(g_lines + g_used, sizeof(g_lines) - g_used, "%s %lld %ld\n", label, t, result);
  if (n > 0 && (size_t)n < sizeof(g_lines) - g_used) g_used += (size_t)n;
  pthread_mutex_unlock(&g_lines_lock);
}

/* Runahead: a timerfd every 2 ms on a thread of its own, 5 times (a poll, then the read). */
static void* ahead_ticks(void* arg) {
  (void)arg;
  const int t = timerfd_create(CLOCK_MONOTONIC, 0);
  struct itimerspec its = {.it_interval = {0, 2000000}, .it_value = {0, 2000000}};
  timerfd_settime(t, 0, &its, NULL);
  char label[16];
  for (int i = 1; i <= 5; ++i) {
    struct pollfd p = {t, POLLIN, 0};
    uint64_t n = 0;
    if (poll(&p, 1, -1) != 1 || read(t, &n, sizeof(n)) != sizeof(n)) return NULL;
    snprintf(label, sizeof(label), "tick%d", i);
    report_later(label, (long)n);
  }
  close(t);
  return NULL;
}

/* Runahead: a thread asleep in the kernel where the library does not see it. */
static int g_never[2];
static void* ahead_outside(void* arg) {
  (void)arg;
  char c;
  (void)read(g_never[0], &c, 1);
  return NULL;
}

/* Runahead through sends: sleeps to 2, 3, 4, 5, 7 and 8 ms and, at 3 and 5 ms, "sends" 080#, at
 * 4 ms 680#0102030405060708 and at 7 ms 181#, as the bus library tells the clock's library of
 * a frame it put in a socket's ring (wheelhil_vtime_note_frame_sent; the frames go nowhere). */
static void ahead_sends(void) {
  void (*note)(const void*, size_t) =
      (void (*)(const void*, size_t))dlsym(RTLD_DEFAULT, "wheelhil_vtime_note_frame_sent");
  static const struct {
    int ms;
    uint32_t id;
    uint8_t len;
  } kSteps[] = {{2, 0, 255},   {3, 0x080, 0}, {4, 0x680, 8},
                {5, 0x080, 0}, {7, 0x181, 0}, {8, 0, 255}};
  /* A timer armed once starts the library's agent thread, which a grant wakes (as a firmware's
   * fd waits do). */
  const int timer = timerfd_create(CLOCK_MONOTONIC, 0);
  struct itimerspec never = {{0, 0}, {0, 0}};
  timerfd_settime(timer, 0, &never, NULL);
  char label[16];
  for (size_t i = 0; i < sizeof(kSteps) / sizeof(kSteps[0]); ++i) {
    struct timespec at = {0, 0};
    const int64_t t = g_start + (int64_t)kSteps[i].ms * 1000000;
    at.tv_sec = t / 1000000000;
    at.tv_nsec = t % 1000000000;
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, NULL);
    if (kSteps[i].len != 255 && note != NULL) {
      uint8_t frame[16] = {0};
      memcpy(frame, &kSteps[i].id, 4);
      frame[4] = kSteps[i].len;
      for (int b = 0; b < kSteps[i].len; ++b) frame[8 + b] = (uint8_t)(b + 1);
      note(frame, sizeof(frame));
    }
    snprintf(label, sizeof(label), "at%d", kSteps[i].ms);
    report_later(label, note != NULL);
  }
  fputs(g_lines, stdout);
}

/* A kernel CAN socket on $WHEELHIL_VCAN (vcan0 in the user-mode-linux guest) that takes its
 * own frames with SO_TIMESTAMPNS: one frame sent and read back with recvmsg. Prints the receive
 * stamp and CLOCK_REALTIME, both in ns (the clock's library makes the stamp the virtual one). */
static int can_stamps(void) {
  const char* iface = getenv("WHEELHIL_VCAN");
  if (iface == NULL) return 3;
  const int s = socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (s < 0) return 4;
  const int on = 1;
  setsockopt(s, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &on, sizeof(on));
  setsockopt(s, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on));
  struct sockaddr_can addr = {0};
  addr.can_family = AF_CAN;
  addr.can_ifindex = (int)if_nametoindex(iface);
  if (bind(s, (struct sockaddr*)&addr, sizeof(addr)) != 0) return 5;
  struct can_frame f = {0};
  f.can_id = 0x123;
  f.len = 1;
  if (write(s, &f, sizeof(f)) != (ssize_t)sizeof(f)) return 6;
  char control[CMSG_SPACE(sizeof(struct timespec))];
  struct iovec io = {&f, sizeof(f)};
  struct msghdr m = {0};
  m.msg_iov = &io;
  m.msg_iovlen = 1;
  m.msg_control = control;
  m.msg_controllen = sizeof(control);
  if (recvmsg(s, &m, 0) != (ssize_t)sizeof(f)) return 7;
  long long stamp = -1;
  for (struct cmsghdr* c = CMSG_FIRSTHDR(&m); c != NULL; c = CMSG_NXTHDR(&m, c)) {
    if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_TIMESTAMPNS) {
      struct timespec ts;
      memcpy(&ts, CMSG_DATA(c), sizeof(ts));
      stamp = (long long)ts.tv_sec * 1000000000 + ts.tv_nsec;
    }
  }
  struct timespec now;
  clock_gettime(CLOCK_REALTIME, &now);
  printf("stamp %lld 0\nrealtime %lld 0\n", stamp,
         (long long)now.tv_sec * 1000000000 + now.tv_nsec);
  return 0;
}

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  g_start = mono();
  const char* what = argv[1];
  if (strcmp(what, "can_stamps") == 0) return can_stamps();
  if (strcmp(what, "ahead_sends") == 0) {
    ahead_sends();
    return 0;
  }
  if (strcmp(what, "ahead") == 0 || strcmp(what, "ahead_outside") == 0) {
    /* Sleeps of the main thread (3, 6, 9, 12 ms) and a timerfd's ticks (2 .. 10 ms) in one
     * order; with a thread blocked in the kernel outside the library's waits. */
    pthread_t outside;
    if (strcmp(what, "ahead_outside") == 0) {
      if (pipe(g_never) != 0) return 1;
      pthread_create(&outside, NULL, ahead_outside, NULL);
    }
    pthread_t ticks;
    pthread_create(&ticks, NULL, ahead_ticks, NULL);
    char label[16];
    for (int i = 1; i <= 4; ++i) {
      usleep(3000);
      snprintf(label, sizeof(label), "sleep%d", i);
      report_later(label, 0);
    }
    pthread_join(ticks, NULL);
    struct timespec req = {0, 20000000};
    report_later("late", nanosleep(&req, NULL)); /* 32 ms: beyond a short grant */
    fputs(g_lines, stdout);
    return 0;
  } else if (strcmp(what, "sleeps") == 0) {
    report("start", 0);
    sleep(30);
    report("sleep30", 0);
    struct timespec req = {0, 250000000};
    report("nanosleep", nanosleep(&req, NULL));
    report("usleep", usleep(1500));
    struct timespec abs;
    clock_gettime(CLOCK_MONOTONIC, &abs);
    abs.tv_sec += 2;
    report("clock_nanosleep_abs", clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &abs, NULL));
    struct timeval tv;
    gettimeofday(&tv, NULL);
    printf("realtime_s %lld\n", (long long)tv.tv_sec);
  } else if (strcmp(what, "polls") == 0) {
    int p[2];
    if (pipe(p) != 0) return 1;
    struct pollfd pf = {p[0], POLLIN, 0};
    report("poll", poll(&pf, 1, 5));
    fd_set rd;
    FD_ZERO(&rd);
    FD_SET(p[0], &rd);
    struct timeval tv = {0, 15000};
    report("select", select(p[0] + 1, &rd, NULL, NULL, &tv));
    const int ep = epoll_create1(0);
    struct epoll_event ev = {.events = EPOLLIN, .data.fd = p[0]};
    epoll_ctl(ep, EPOLL_CTL_ADD, p[0], &ev);
    struct epoll_event out;
    report("epoll_wait", epoll_wait(ep, &out, 1, 3));
    struct timespec ts = {0, 7000000};
    report("ppoll", ppoll(&pf, 1, &ts, NULL));
    // Readiness before the deadline ends the wait at once.
    if (write(p[1], "x", 1) != 1) return 1;
    report("poll_ready", poll(&pf, 1, 1000));
  } else if (strcmp(what, "timerfd") == 0) {
    const int t = timerfd_create(CLOCK_MONOTONIC, 0);
    struct itimerspec its = {.it_interval = {0, 20000000}, .it_value = {0, 7000000}};
    timerfd_settime(t, 0, &its, NULL);
    for (int i = 0; i < 3; ++i) {
      uint64_t n = 0;
      if (read(t, &n, sizeof(n)) != sizeof(n)) return 1;
      report("tick", (long)n);
    }
    struct itimerspec cur;
    timerfd_gettime(t, &cur);
    printf("remaining_ns %ld\n", cur.it_value.tv_nsec);
    // Two periods slept through: one read returns both expirations.
    usleep(45000);
    uint64_t n = 0;
    if (read(t, &n, sizeof(n)) != sizeof(n)) return 1;
    report("overrun", (long)n);
    close(t);
  } else if (strcmp(what, "cond") == 0) {
    pthread_mutex_lock(&g_m);
    struct timespec abs = in_ms(CLOCK_MONOTONIC, 50);
    int rc;
    do rc = pthread_cond_clockwait(&g_c, &g_m, CLOCK_MONOTONIC, &abs);
    while (rc == 0);
    report("clockwait", rc == ETIMEDOUT);
    abs = in_ms(CLOCK_REALTIME, 20);
    do rc = pthread_cond_timedwait(&g_c, &g_m, &abs);
    while (rc == 0);
    report("timedwait", rc == ETIMEDOUT);
    // A condition on CLOCK_MONOTONIC (as CPython's): pthread_cond_timedwait takes its clock.
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_cond_t mono;
    pthread_cond_init(&mono, &ca);
    abs = in_ms(CLOCK_MONOTONIC, 5);
    do rc = pthread_cond_timedwait(&mono, &g_m, &abs);
    while (rc == 0);
    report("timedwait_monotonic", rc == ETIMEDOUT);
    // Another thread signals after 10 ms of its own sleep: the untimed wait ends then.
    pthread_t t;
    pthread_create(&t, NULL, signaller, NULL);
    while (!g_flag) pthread_cond_wait(&g_c, &g_m);
    pthread_mutex_unlock(&g_m);
    report("signalled", 1);
    pthread_join(t, NULL);
  } else if (strcmp(what, "sem") == 0) {
    sem_init(&g_sem, 0, 0);
    struct timespec abs = in_ms(CLOCK_REALTIME, 30);
    const int rc = sem_timedwait(&g_sem, &abs);
    report("sem_timedwait", rc == -1 && errno == ETIMEDOUT);
    pthread_t t;
    pthread_create(&t, NULL, poster, NULL);
    abs = in_ms(CLOCK_MONOTONIC, 100);
    report("sem_clockwait_posted", sem_clockwait(&g_sem, CLOCK_MONOTONIC, &abs) == 0);
    pthread_join(t, NULL);
  } else if (strcmp(what, "mutex") == 0) {
    pthread_t t;
    pthread_create(&t, NULL, holder, (void*)(intptr_t)12500);
    usleep(100);  // the holder has it
    struct timespec abs = in_ms(CLOCK_REALTIME, 50);
    report("timedlock", pthread_mutex_timedlock(&g_held, &abs) == 0);
    pthread_mutex_unlock(&g_held);
    pthread_join(t, NULL);
    pthread_create(&t, NULL, holder, (void*)(intptr_t)20000);
    usleep(100);
    abs = in_ms(CLOCK_MONOTONIC, 5);
    report("clocklock_timeout", pthread_mutex_clocklock(&g_held, CLOCK_MONOTONIC, &abs) == ETIMEDOUT);
    pthread_join(t, NULL);
  } else if (strcmp(what, "syscall") == 0) {
    struct timespec ts;
    syscall(SYS_clock_gettime, CLOCK_MONOTONIC, &ts);
    report("raw_clock", (long)((int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec - g_start));
    struct timespec req = {0, 3000000};
    report("raw_nanosleep", syscall(SYS_nanosleep, &req, NULL));
    struct timespec rel = {0, 4000000};
    const long rc = syscall(SYS_futex, &g_word, FUTEX_WAIT_PRIVATE, 0, &rel, NULL, 0);
    report("futex_timeout", rc == -1 && errno == ETIMEDOUT);
    pthread_t t;
    pthread_create(&t, NULL, futex_waker, NULL);
    struct timespec abs;
    clock_gettime(CLOCK_MONOTONIC, &abs);
    abs.tv_sec += 1;  // the waker comes first (2 ms)
    long r2;
    do r2 = syscall(SYS_futex, &g_word, FUTEX_WAIT_BITSET_PRIVATE, 0, &abs, NULL,
                    FUTEX_BITSET_MATCH_ANY);
    while (r2 == 0 && __atomic_load_n(&g_word, __ATOMIC_SEQ_CST) == 0);
    report("futex_woken", __atomic_load_n(&g_word, __ATOMIC_SEQ_CST) == 1);
    pthread_join(t, NULL);
  } else if (strcmp(what, "timers") == 0) {
    struct sigaction sa;
    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = on_alarm;
    sigaction(SIGALRM, &sa, NULL);
    alarm(2);
    report("alarm_left", alarm(1));  // replaces it: 2 s were left
    while (g_alarms == 0) pause();
    report("alarm", g_alarms);
    // A POSIX timer every 5 ms from 5 ms, its signal taken with sigwaitinfo.
    sigset_t usr;
    sigemptyset(&usr);
    sigaddset(&usr, SIGUSR1);
    pthread_sigmask(SIG_BLOCK, &usr, NULL);
    struct sigevent sev;
    memset(&sev, 0, sizeof(sev));
    sev.sigev_notify = SIGEV_SIGNAL;
    sev.sigev_signo = SIGUSR1;
    sev.sigev_value.sival_int = 7;
    timer_t tid;
    timer_create(CLOCK_MONOTONIC, &sev, &tid);
    struct itimerspec its = {.it_interval = {0, 5000000}, .it_value = {0, 5000000}};
    timer_settime(tid, 0, &its, NULL);
    for (int i = 0; i < 3; ++i) {
      siginfo_t info;
      sigwaitinfo(&usr, &info);
      report("posix_timer", info.si_code == SI_TIMER && info.si_value.sival_int == 7);
    }
    timer_delete(tid);
    // SIGEV_THREAD: the function runs in a new thread 8 ms from now.
    sem_init(&g_fired, 0, 0);
    memset(&sev, 0, sizeof(sev));
    sev.sigev_notify = SIGEV_THREAD;
    sev.sigev_notify_function = on_timer_thread;
    sev.sigev_value.sival_int = 42;
    timer_create(CLOCK_MONOTONIC, &sev, &tid);
    struct itimerspec once = {.it_interval = {0, 0}, .it_value = {0, 8000000}};
    timer_settime(tid, 0, &once, NULL);
    sem_wait(&g_fired);
    report("thread_timer", 1);
    struct itimerval it = {.it_interval = {0, 0}, .it_value = {0, 3000}};
    g_alarms = 0;
    setitimer(ITIMER_REAL, &it, NULL);
    while (g_alarms == 0) pause();
    report("setitimer", g_alarms);
  } else if (strcmp(what, "settime") == 0) {
    /* Every way to set the clock moves the virtual CLOCK_REALTIME (the test drops CAP_SYS_TIME:
     * a call that reached the kernel would fail with EPERM). */
    struct timespec ts = {1900000000, 0};
    report("clock_settime", clock_settime(CLOCK_REALTIME, &ts) == 0 ? realtime_s() : -errno);
    struct timeval tv = {2000000000, 0};
    report("settimeofday", settimeofday(&tv, NULL) == 0 ? realtime_s() : -errno);
    struct timex tx;
    memset(&tx, 0, sizeof(tx));
    tx.modes = ADJ_SETOFFSET;
    tx.time.tv_sec = 5;
    report("adjtimex_setoffset", adjtimex(&tx) == TIME_OK ? realtime_s() : -errno);
    struct timeval delta = {10, 0};
    report("adjtime", adjtime(&delta, NULL) == 0 ? realtime_s() : -errno);
    memset(&tx, 0, sizeof(tx));
    tx.modes = ADJ_FREQUENCY;
    tx.freq = 1234;
    adjtimex(&tx);
    memset(&tx, 0, sizeof(tx));
    report("adjtimex_read_freq", adjtimex(&tx) == TIME_OK ? tx.freq : -errno);
    report("adjtimex_read_time", tx.time.tv_sec);
    int (*stime_fn)(const time_t*) = (int (*)(const time_t*))dlsym(RTLD_DEFAULT, "stime");
    time_t t = 2100000000;
    report("stime", stime_fn != NULL && stime_fn(&t) == 0 ? realtime_s() : -1);
    ts.tv_sec = 2200000000;
    report("syscall_settime", syscall(SYS_clock_settime, CLOCK_REALTIME, &ts) == 0 ? realtime_s() : -errno);
    report("settime_monotonic", clock_settime(CLOCK_MONOTONIC, &ts) == -1 && errno == EINVAL);
    sleep(2);
    report("after_sleep", realtime_s());
  } else if (strcmp(what, "forever") == 0) {
    void* (*fns[6])(void*) = {sleep_forever, abs_sleep_forever, cond_forever, ppoll_forever,
                              select_forever, sem_forever};
    for (int i = 0; i < 6; ++i) {
      pthread_t th;
      pthread_create(&th, NULL, fns[i], NULL);
      pthread_detach(th);
    }
    int tfd = timerfd_create(CLOCK_MONOTONIC, 0);
    struct itimerspec far = {.it_interval = {LONG_MAX, 0}, .it_value = {LONG_MAX, 0}};
    timerfd_settime(tfd, 0, &far, NULL);
    struct itimerspec cur;
    timerfd_gettime(tfd, &cur);
    usleep(50000);
    int ended = 0;
    for (int i = 0; i < 6; ++i) ended += g_ended[i];
    report("forever_ended", ended);
    report("timerfd_far", cur.it_value.tv_sec > 1000000000L);
    fflush(stdout);
    _exit(0); /* the waiting threads go with the process */
  } else if (strcmp(what, "nested") == 0) {
    struct sigaction sa;
    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = on_alarm_sleeping;
    sa.sa_flags = SA_RESTART;
    sigaction(SIGALRM, &sa, NULL);
    struct itimerval it = {.it_interval = {0, 0}, .it_value = {0, 10000}};
    setitimer(ITIMER_REAL, &it, NULL);
    pthread_mutex_lock(&g_m);
    struct timespec abs = in_ms(CLOCK_REALTIME, 50);
    int rc;
    do rc = pthread_cond_timedwait(&g_c, &g_m, &abs);
    while (rc == 0);
    pthread_mutex_unlock(&g_m);
    report("interrupted_cond", rc == ETIMEDOUT);
  } else if (strcmp(what, "closefds") == 0) {
    report("poll", poll(NULL, 0, 5));  /* the main thread's wake-up exists */
    pthread_t th;
    pthread_create(&th, NULL, timed_polls, NULL);
    usleep(1000);
    report("close_range", close_range(3, ~0U, 0));
    report("after_close_range", poll(NULL, 0, 5));
    closefrom(3);
    report("after_closefrom", poll(NULL, 0, 5));
    for (int fd = 3; fd < 64; ++fd) close(fd); /* a daemon's loop */
    report("after_close_loop", poll(NULL, 0, 5));
    report("dup2_onto", dup2_onto_eventfds() >= 1);
    report("after_dup2", poll(NULL, 0, 5));
    const int tfd = timerfd_create(CLOCK_MONOTONIC, 0);
    struct itimerspec once = {.it_interval = {0, 0}, .it_value = {0, 3000000}};
    timerfd_settime(tfd, 0, &once, NULL);
    uint64_t n = 0;
    report("timerfd_after", read(tfd, &n, sizeof(n)) == sizeof(n) ? (long)n : -1);
    pthread_join(th, NULL);
  } else if (strcmp(what, "fdfull") == 0) {
    struct rlimit rl = {32, 32};
    setrlimit(RLIMIT_NOFILE, &rl);
    int first = -1, last = -1, fd;
    while ((fd = open("/dev/null", O_RDONLY)) >= 0) {
      if (first < 0) first = fd;
      last = fd;
    }
    report("fd_table_full", errno == EMFILE);
    pthread_t th;
    pthread_create(&th, NULL, first_wait_without_fds, NULL);
    pthread_join(th, NULL);
    /* (LeakSanitizer, in the ASan build, needs descriptors at exit.) */
    if (first >= 0) close_range((unsigned)first, (unsigned)last, 0);
  } else if (strcmp(what, "reexec") == 0) {
    /* Re-exec itself without the clock library (LD_PRELOAD cleared), as some launchers do. */
    usleep(1000); /* on the clock first */
    unsetenv("LD_PRELOAD");
    execl(argv[0], argv[0], "reexec-child", (char*)NULL);
    return 1;
  } else if (strcmp(what, "reexec-child") == 0) {
    struct timespec req = {0, 300000000};
    nanosleep(&req, NULL); /* the host's clock */
  } else if (strcmp(what, "spin") == 0) {
    report("start", 0);
    for (;;) mono();
  } else {
    return 2;
  }
  return 0;
}
