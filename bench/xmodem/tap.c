/* A serial link between two programs, as `socat pty,raw,echo=0,link=A pty,raw,echo=0,link=B`
 * makes one, that also records every byte each side sent with the time it reached the link, and
 * can carry the bytes at a line rate and damage them (seeded) as a noisy wire does. The benchmark
 * times the phases of a transfer from this record, the same way for every pair of programs.
 *
 * usage: tap LINK_A LINK_B LOG [BAUD [FLIP DROP DUP SEED]]
 *   LOG: one line per read, "SECONDS a|b HEX" (CLOCK_REALTIME, the bytes as sent, before damage).
 *   BAUD: 0 = as fast as the ptys go; otherwise each direction carries one character per 10 bits.
 *   FLIP, DROP, DUP: per byte and direction, the chance that it is XORed with a random non-zero
 *   mask, lost, or delivered twice; SEED makes the damage repeatable (each direction its own).
 * Runs until SIGTERM or SIGINT; the slaves are held open, so a program may close and reopen its
 * side (as socat's ptys allow).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

static volatile sig_atomic_t stop;
static void on_signal(int sig)
{
  (void)sig;
  stop = 1;
}

static double now_s(void)
{
  struct timespec t;
  clock_gettime(CLOCK_REALTIME, &t);
  return t.tv_sec + t.tv_nsec * 1e-9;
}

struct direction
{
  int from, to;  /* master descriptors */
  char name;
  uint64_t random;
  /* bytes on their way, each with the time it leaves the wire */
  unsigned char* bytes;
  double* due;
  size_t head, tail, capacity;
  double wire_free;
  unsigned long flipped, dropped, doubled;
};

static double uniform(struct direction* d)
{
  /* xorshift64*: enough for a repeatable noise pattern */
  d->random ^= d->random >> 12;
  d->random ^= d->random << 25;
  d->random ^= d->random >> 27;
  return (double)((d->random * 2685821657736338717ULL) >> 11) / 9007199254740992.0;
}

static void enqueue(struct direction* d, unsigned char byte, double at, double char_time)
{
  if (d->tail == d->capacity)
  {
    if (d->head > 0)
    {
      memmove(d->bytes, d->bytes + d->head, d->tail - d->head);
      memmove(d->due, d->due + d->head, (d->tail - d->head) * sizeof(double));
      d->tail -= d->head;
      d->head = 0;
    }
    if (d->tail == d->capacity)
    {
      d->capacity *= 2;
      d->bytes = realloc(d->bytes, d->capacity);
      d->due = realloc(d->due, d->capacity * sizeof(double));
    }
  }
  const double start = d->wire_free > at ? d->wire_free : at;
  d->wire_free = start + char_time;
  d->bytes[d->tail] = byte;
  d->due[d->tail] = d->wire_free;
  ++d->tail;
}

static int make_pty(const char* link)
{
  int master, slave;
  if (openpty(&master, &slave, NULL, NULL, NULL) != 0)
  {
    perror("openpty");
    exit(1);
  }
  struct termios tio;
  tcgetattr(slave, &tio);
  cfmakeraw(&tio);
  tcsetattr(slave, TCSANOW, &tio);
  unlink(link);
  if (symlink(ptsname(master), link) != 0)
  {
    perror(link);
    exit(1);
  }
  fcntl(master, F_SETFL, O_NONBLOCK);
  return master; /* the slave stays open until exit */
}

int main(int argc, char** argv)
{
  if (argc < 4)
  {
    fprintf(stderr, "usage: tap LINK_A LINK_B LOG [BAUD [FLIP DROP DUP SEED]]\n");
    return 2;
  }
  const double baud = argc > 4 ? atof(argv[4]) : 0;
  const double flip = argc > 5 ? atof(argv[5]) : 0, drop = argc > 6 ? atof(argv[6]) : 0,
               dup = argc > 7 ? atof(argv[7]) : 0;
  const uint64_t seed = argc > 8 ? strtoull(argv[8], NULL, 10) : 1;
  const double char_time = baud > 0 ? 10.0 / baud : 0;
  FILE* log = fopen(argv[3], "w");
  if (!log)
  {
    perror(argv[3]);
    return 1;
  }
  setvbuf(log, NULL, _IOFBF, 1 << 20);
  signal(SIGTERM, on_signal);
  signal(SIGINT, on_signal);
  const int a = make_pty(argv[1]), b = make_pty(argv[2]);
  struct direction dirs[2] = {{.from = a, .to = b, .name = 'a', .random = seed * 2 + 1},
                              {.from = b, .to = a, .name = 'b', .random = seed * 2 + 12345}};
  for (int i = 0; i < 2; ++i)
  {
    dirs[i].capacity = 1 << 16;
    dirs[i].bytes = malloc(dirs[i].capacity);
    dirs[i].due = malloc(dirs[i].capacity * sizeof(double));
  }
  unsigned char buffer[65536];
  while (!stop)
  {
    /* wait for input, or until the next byte in flight is due */
    double next = -1;
    for (int i = 0; i < 2; ++i)
      if (dirs[i].head < dirs[i].tail && (next < 0 || dirs[i].due[dirs[i].head] < next))
        next = dirs[i].due[dirs[i].head];
    struct pollfd fds[2] = {{a, POLLIN, 0}, {b, POLLIN, 0}};
    struct timespec wait = {0, 100 * 1000 * 1000};
    if (next >= 0)
    {
      double left = next - now_s();
      if (left < 0)
        left = 0;
      wait.tv_sec = (time_t)left;
      wait.tv_nsec = (long)((left - wait.tv_sec) * 1e9);
    }
    ppoll(fds, 2, &wait, NULL);
    for (int i = 0; i < 2; ++i)
    {
      struct direction* d = &dirs[i];
      if (fds[i].revents & POLLIN)
      {
        const ssize_t n = read(d->from, buffer, sizeof(buffer));
        if (n > 0)
        {
          const double t = now_s();
          fprintf(log, "%.6f %c ", t, d->name);
          for (ssize_t k = 0; k < n; ++k)
            fprintf(log, "%02x", buffer[k]);
          fputc('\n', log);
          for (ssize_t k = 0; k < n; ++k)
          {
            unsigned char byte = buffer[k];
            if (flip > 0 && uniform(d) < flip)
            {
              byte ^= (unsigned char)(1 + (unsigned)(uniform(d) * 255));
              ++d->flipped;
            }
            if (drop > 0 && uniform(d) < drop)
            {
              ++d->dropped;
              continue;
            }
            enqueue(d, byte, t, char_time);
            if (dup > 0 && uniform(d) < dup)
            {
              enqueue(d, byte, t, char_time);
              ++d->doubled;
            }
          }
        }
      }
      /* deliver what is due */
      const double t = now_s();
      size_t end = d->head;
      while (end < d->tail && d->due[end] <= t)
        ++end;
      while (d->head < end)
      {
        const ssize_t w = write(d->to, d->bytes + d->head, end - d->head);
        if (w <= 0)
          break; /* the other side's buffer is full: try again at the next round */
        d->head += (size_t)w;
      }
    }
  }
  for (int i = 0; i < 2; ++i)
    fprintf(log, "# %c flipped=%lu dropped=%lu doubled=%lu\n", dirs[i].name, dirs[i].flipped, dirs[i].dropped,
            dirs[i].doubled);
  fclose(log);
  unlink(argv[1]);
  unlink(argv[2]);
  return 0;
}
