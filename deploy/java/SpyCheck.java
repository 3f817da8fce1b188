// `deploy/lcm-spy --check`: opens lcm-spy's message view for every rcal type, the way a user does,
// and fails if one cannot be opened or drawn. Run under a display (deploy/lcm-spy starts Xvfb):
//   java -cp lcm.jar:jchart2d.jar:rcal_lcmtypes.jar deploy/java/SpyCheck.java rcal.imu_sample_t ...
//
// 1. Starts lcm.spy.Spy itself (its window, its channel table) on a memq:// LCM, so nothing goes on
//    a network and no multicast route is needed.
// 2. Publishes one message of each class named on the command line through Spy's own LCM, every
//    field filled (arrays of 2 where the length field is num_*), on a channel named after the type.
// 3. Waits until Spy lists every channel decoded (its type found by fingerprint, no decode error).
// 4. Double-clicks each row of Spy's channel table (a MOUSE_CLICKED event with click count 2 sent
//    to the table, as the AWT sends a user's double-click), which is how a user opens a message
//    view, and requires a visible viewer window showing that message.
// 5. Publishes each message again (the update path of an open view), then draws every view into
//    an image (ObjectPanel.paint: the field table and the sparklines, which need jchart2d).
// Any exception, on this thread or on the event dispatch thread, fails the check (exit 1) with its
// stack trace on stderr; success prints one line per view and exits 0.

import java.awt.EventQueue;
import java.awt.Rectangle;
import java.awt.event.MouseEvent;
import java.awt.image.BufferedImage;
import java.lang.reflect.Array;
import java.lang.reflect.Field;
import java.lang.reflect.Modifier;
import java.util.ArrayList;
import java.util.Collections;
import java.util.List;
import javax.swing.JFrame;
import javax.swing.JTable;
import lcm.lcm.LCM;
import lcm.lcm.LCMEncodable;
import lcm.spy.ChannelData;
import lcm.spy.Spy;

public class SpyCheck {
  static final List<Throwable> uncaught = Collections.synchronizedList(new ArrayList<>());

  static Object field(Object o, String name) throws Exception {
    Field f = o.getClass().getDeclaredField(name);
    f.setAccessible(true);
    return f.get(o);
  }

  // A value for every field: numbers from a counter, strings, arrays of 2 where the length field
  // is num_* (lcm-gen allocates fixed-size arrays in the constructor; variable ones are null).
  static int counter = 1;

  static Object element(Class<?> t) throws Exception {
    if (t == double.class) return 0.125 * counter++;
    if (t == float.class) return (float) (0.125 * counter++);
    if (t == long.class) return (long) counter++;
    if (t == int.class) return counter++;
    if (t == short.class) return (short) counter++;
    if (t == byte.class) return (byte) (counter++ & 0x3f);
    if (t == boolean.class) return (counter++ % 2) == 0;
    if (t == String.class) return "rcal" + counter++;
    if (LCMEncodable.class.isAssignableFrom(t)) return filled(t);
    throw new IllegalArgumentException("no value for " + t);
  }

  static void fillArray(Object a) throws Exception {
    Class<?> c = a.getClass().getComponentType();
    for (int i = 0; i < Array.getLength(a); ++i) {
      Object e = Array.get(a, i);
      if (c.isArray()) {
        if (e != null) fillArray(e);
      } else {
        Array.set(a, i, element(c));
      }
    }
  }

  static Object filled(Class<?> c) throws Exception {
    Object o = c.getConstructor().newInstance();
    List<Field> fields = new ArrayList<>();
    for (Field f : c.getFields()) {
      int m = f.getModifiers();
      if (!Modifier.isStatic(m) && !Modifier.isFinal(m)) fields.add(f);
    }
    for (Field f : fields) {  // lengths first
      if (f.getType() == int.class && IsLength(f.getName())) f.setInt(o, 2);
    }
    for (Field f : fields) {
      Class<?> t = f.getType();
      if (t == int.class && IsLength(f.getName())) continue;
      if (t.isArray()) {
        Object a = f.get(o);
        if (a == null) a = Array.newInstance(t.getComponentType(), 2);
        fillArray(a);
        f.set(o, a);
      } else {
        f.set(o, element(t));
      }
    }
    return o;
  }

  // The array length fields of rcal's types: num_* and NEXT_POSES' count.
  static boolean IsLength(String name) {
    return name.startsWith("num_") || name.equals("count");
  }

  static void fail(String what, Throwable e) {
    System.err.println("lcm-spy --check: FAILED: " + what);
    if (e != null) e.printStackTrace();
    System.exit(1);
  }

  static void onEdt(Runnable r) throws Exception {
    try {
      EventQueue.invokeAndWait(r);
    } catch (java.lang.reflect.InvocationTargetException e) {
      throw new Exception(e.getCause());
    }
  }

  static void checkUncaught(String when) {
    if (!uncaught.isEmpty()) fail("exception " + when, uncaught.get(0));
  }

  @SuppressWarnings("unchecked")
  public static void main(String[] args) throws Exception {
    if (args.length == 0) fail("no rcal types given", null);
    Thread.setDefaultUncaughtExceptionHandler((t, e) -> uncaught.add(e));

    Spy spy = new Spy("memq://");
    LCM lcm = (LCM) field(spy, "lcm");
    ArrayList<ChannelData> channels = (ArrayList<ChannelData>) field(spy, "channelList");
    JTable table = (JTable) field(spy, "channelTable");

    List<LCMEncodable> messages = new ArrayList<>();
    for (String name : args) {
      Class<?> c;
      try {
        c = Class.forName(name);
      } catch (Throwable e) {
        fail("type " + name + " not on the classpath", e);
        return;
      }
      messages.add((LCMEncodable) filled(c));
    }
    for (int i = 0; i < args.length; ++i) lcm.publish(args[i], messages.get(i));

    // Spy's subscriber runs on memq's reader thread: wait (up to a minute on a loaded machine)
    // until every channel is listed with its type.
    for (int tries = 0;; ++tries) {
      final int[] decoded = {0};
      onEdt(() -> {
        synchronized (channels) {
          for (ChannelData cd : channels)
            if (cd.cls != null && cd.last != null) decoded[0]++;
        }
      });
      if (decoded[0] == args.length) break;
      if (tries == 600) fail("Spy decoded " + decoded[0] + " of " + args.length + " channels", null);
      Thread.sleep(100);
    }
    checkUncaught("while Spy received the messages");
    for (ChannelData cd : channels) {
      if (cd.nerrors != 0) fail(cd.name + ": " + cd.nerrors + " decode errors in Spy", null);
    }

    // Double-click every row of the channel table.
    for (int row = 0; row < args.length; ++row) {
      final int r = row;
      try {
        onEdt(() -> {
          Rectangle cell = table.getCellRect(r, 0, true);
          int x = cell.x + cell.width / 2, y = cell.y + cell.height / 2;
          long now = System.currentTimeMillis();
          table.dispatchEvent(new MouseEvent(table, MouseEvent.MOUSE_PRESSED, now,
                                             MouseEvent.BUTTON1_DOWN_MASK, x, y, 1, false,
                                             MouseEvent.BUTTON1));
          table.dispatchEvent(new MouseEvent(table, MouseEvent.MOUSE_RELEASED, now, 0, x, y, 1,
                                             false, MouseEvent.BUTTON1));
          table.dispatchEvent(new MouseEvent(table, MouseEvent.MOUSE_CLICKED, now, 0, x, y, 2,
                                             false, MouseEvent.BUTTON1));
        });
      } catch (Exception e) {
        fail("double-click on row " + row + " of lcm-spy's channel table", e.getCause());
      }
    }
    onEdt(() -> {});
    checkUncaught("while opening the message views");
    for (ChannelData cd : channels) {
      JFrame frame = cd.viewerFrame;
      if (frame == null || cd.viewer == null) fail("no message view opened for " + cd.name, null);
      if (!frame.isVisible()) fail("the message view of " + cd.name + " is not visible", null);
    }

    // The update path of an open view, then draw each view.
    for (int i = 0; i < args.length; ++i) lcm.publish(args[i], messages.get(i));
    for (int tries = 0;; ++tries) {
      final int[] updated = {0};
      onEdt(() -> {
        synchronized (channels) {
          for (ChannelData cd : channels)
            if (cd.nreceived == 2) updated[0]++;
        }
      });
      if (updated[0] == args.length) break;
      if (tries == 600) fail("Spy updated " + updated[0] + " of " + args.length + " views", null);
      Thread.sleep(100);
    }
    checkUncaught("while the open views were updated");
    for (ChannelData cd : channels) {
      try {
        onEdt(() -> {
          cd.viewerFrame.validate();
          int w = Math.max(cd.viewer.getWidth(), 400), h = Math.max(cd.viewer.getHeight(), 300);
          BufferedImage image = new BufferedImage(w, h, BufferedImage.TYPE_INT_RGB);
          cd.viewer.paint(image.getGraphics());
          cd.viewerFrame.getRootPane().paint(image.getGraphics());
        });
      } catch (Exception e) {
        fail("drawing the message view of " + cd.name, e.getCause());
      }
      Object shown = field(cd.viewer, "o");
      if (shown == null || shown.getClass() != cd.cls)
        fail("the view of " + cd.name + " does not show a " + cd.cls.getName(), null);
      System.out.println("ok view " + cd.name + " (" + cd.cls.getName() + ", " + cd.nreceived
                         + " received)");
    }
    onEdt(() -> {});
    checkUncaught("while drawing the message views");
    System.exit(0);
  }
}
